"""Benchmark on real robots: every robot of a UTIAS MRCLAM dataset folder against Vicon.

For each robot k of the folder (five iRobot Creates), in one process with BLAS on one thread:

1. every robot's run is imported without a noise model;
2. a noise model is fitted on the *other* robots (``fit_noise_model``, leave-one-out), so
   no figure comes from noise fitted on the run it scores;
3. robot k is imported again with that model (``import_mrclam(..., model=...)``);
4. ``ekf``, ``isam2`` (robust DCS kernel, as the default picks when the model expects
   outliers), ``dead_reckoning`` and the batch solve run on it (``compare_log``);
5. against Vicon, over the poses that have truth: ATE of the final and of the online
   trajectory (anchored: both start at Vicon's first pose, no alignment) and the same
   after the least-squares SE(2) alignment (what the TUM benchmark's ATE and evo's ``-a``
   report: a SLAM map's frame is fixed only by the start pose, and a heading error made
   before the first landmark is seen rotates the whole map), the map error against the
   surveyed landmarks (anchored), the share of NIS values inside the 95 % χ²(2) band, and
   the total time: as ``fgslam run`` times it, with the NIS/NEES work between the steps,
   and of a second run of the estimator alone (that work slows iSAM2's own steps by
   30–50 %, the EKF's by a few per cent: ``time alone s``).

Usage::

    .venv/bin/python -m scripts.bench_mrclam ../shared/data/mrclam/MRCLAM_Dataset6
    .venv/bin/python -m scripts.bench_mrclam FOLDER --figure docs/mrclam_trajectories.png
    .venv/bin/python -m scripts.bench_mrclam FOLDER --robots 1,2 --estimators ekf,isam2 --no-model

``--no-model`` scores the round, unfitted default noise instead (the "before" column).
``--fit-on 1`` fits one model on robot 1 alone and scores every other robot with it (does
a model learned on one Create carry to the others?).
Prints one markdown table row per robot and estimator, then the medians over robots.
"""

from __future__ import annotations

import os

from scripts.common import one_blas_thread

one_blas_thread()

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy.stats import chi2  # noqa: E402

from fgslam.compare import align_se2, apply_se2  # noqa: E402
from fgslam.runner import ESTIMATORS, compare_log, parse_estimator_names, run_estimator  # noqa: E402
from slamio.datasets.mrclam import ROBOT_SUBJECTS, import_mrclam  # noqa: E402
from slamio.log import RunLog  # noqa: E402
from slamio.noise.errors import NoiseModelError  # noqa: E402
from slamio.noise.fit_truth import fit_noise_model  # noqa: E402


def _rmse(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))))


def ate_and_turn(estimate: np.ndarray, truth_xy: np.ndarray, mask: np.ndarray) -> tuple[float, float, float]:
    """(anchored ATE m, SE(2)-aligned ATE m, the aligning rotation rad) over the poses in ``mask``."""
    e, t = np.asarray(estimate)[: len(mask)][mask, :2], truth_xy[mask]
    rotation, translation = align_se2(e, t)
    return _rmse(e, t), _rmse(apply_se2(e, rotation, translation), t), rotation


def ate_pair_m(estimate: np.ndarray, truth_xy: np.ndarray, mask: np.ndarray) -> tuple[float, float]:
    """(anchored ATE, SE(2)-aligned ATE) over the poses in ``mask``, metres."""
    return ate_and_turn(estimate, truth_xy, mask)[:2]


def nis_inside(values) -> float | None:
    v = np.asarray(values if values is not None else [], float)
    v = v[np.isfinite(v)]
    if not len(v):
        return None
    low, high = chi2.ppf(0.025, 2), chi2.ppf(0.975, 2)
    return float(np.mean((v >= low) & (v <= high)))


def score_robot(log: RunLog, names: list[str], *, time_alone: bool = False) -> dict:
    """Run the estimators on one log and score them against its truth; with ``time_alone``
    also time each estimator in a second run without the NIS/NEES work (``alone_s``)."""
    steps = log.steps()
    mask = np.array([s.truth is not None for s in steps])
    truth_xy = np.array([[s.truth.x_m, s.truth.y_m] if s.truth else [np.nan, np.nan] for s in steps])
    surveyed = {i: (t.x_m, t.y_m) for i, t in log.truth_landmarks().items()}
    comparison = compare_log(log, names)
    out = {}
    for run in comparison.runs:
        row: dict = {"total_s": run.total_time_s}
        if time_alone and run.name in ESTIMATORS:  # the NIS/NEES work between steps slows iSAM2's
            row["alone_s"] = run_estimator(ESTIMATORS[run.name](log.header), steps, covariances=False)[0].total_time_s
        row["ate_final_m"], row["ate_final_aligned_m"], rotation = ate_and_turn(run.final, truth_xy, mask)
        row["rotation_deg"] = math.degrees(rotation)
        if run.online is not None:
            row["ate_online_m"], row["ate_online_aligned_m"] = ate_pair_m(run.online, truth_xy, mask)
        common = sorted(set(run.landmarks) & set(surveyed))
        if common:
            row["map_rmse_m"] = _rmse(np.array([run.landmarks[i] for i in common]), np.array([surveyed[i] for i in common]))
        row["nis_inside"] = nis_inside(run.nis)
        row["final"] = np.asarray(run.final)[:, :2].tolist()
        out[run.name] = row
    out["_truth"] = {"xy": truth_xy.tolist(), "landmarks": {str(k): v for k, v in surveyed.items()}}
    return out


def _fmt(value, digits=3) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def print_table(results: dict[int, dict], names: list[str]) -> None:
    columns = ["ate_final_m", "ate_online_m", "ate_final_aligned_m", "ate_online_aligned_m", "map_rmse_m", "nis_inside",
               "total_s", "alone_s"]
    print("| robot | estimator | ATE final m | ATE online m | ATE final, aligned m | ATE online, aligned m | map RMSE m "
          "| NIS in band | time s | time alone s |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for robot, res in results.items():
        for name in names + ["batch"]:
            if name in res:
                r = res[name]
                print(f"| {robot} | {name} | " + " | ".join(_fmt(r.get(c)) for c in columns) + " |")
    print("| **median** | | | | | | | | | |")
    for name in names + ["batch"]:
        cells = []
        for c in columns:
            values = [res[name].get(c) for res in results.values() if name in res and res[name].get(c) is not None]
            cells.append(_fmt(float(np.median(values))) if values else "-")
        print(f"| median | {name} | " + " | ".join(cells) + " |")


def draw_figure(results: dict[int, dict], path: str, names: list[str]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(results), figsize=(4.2 * len(results), 6.5), squeeze=False)
    colours = {"ekf": "tab:blue", "ekf-fej": "tab:purple", "isam2": "tab:red", "dead_reckoning": "0.6"}
    for ax, (robot, res) in zip(axes[0], results.items()):
        truth = np.array(res["_truth"]["xy"])
        ax.plot(truth[:, 0], truth[:, 1], color="k", lw=2.2, alpha=0.5, label="Vicon")
        for name in names:
            if name in res:
                xy = np.array(res[name]["final"])
                ax.plot(xy[:, 0], xy[:, 1], lw=0.9, color=colours.get(name), label=name)
        lm = np.array(list(res["_truth"]["landmarks"].values()))
        ax.scatter(lm[:, 0], lm[:, 1], marker="x", color="k", s=30, label="surveyed landmarks", zorder=5)
        ates = ", ".join(f"{n} {res[n]['ate_final_m']:.2f}" for n in names if n in res and n != "dead_reckoning")
        ax.set_title(f"robot {robot}\nATE m: {ates}", fontsize=9)
        ax.set_aspect("equal")
        ax.set_xlim(-2.5, 6.5)
        ax.set_ylim(-6.5, 6.5)
        ax.grid(alpha=0.3)
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=len(labels), fontsize=9)
    fig.suptitle("MRCLAM: final trajectories over Vicon (noise fitted on the other robots)")
    fig.tight_layout(rect=(0, 0.05, 1, 0.93))
    fig.savefig(path, dpi=90)
    print(f"wrote {path}")


def raw_logs(folder: str) -> dict[int, RunLog]:
    """Every robot of an MRCLAM folder, imported without a noise model (every robot is needed
    to fit the others' models)."""
    raw = {}
    for k in ROBOT_SUBJECTS:
        if os.path.exists(os.path.join(folder, f"Robot{k}_Odometry.dat")):
            header, records = import_mrclam(folder, k)
            raw[k] = RunLog(f"{folder}/robot{k} (raw)", header, tuple(records))
    return raw


def leave_one_out(folder: str, robot: int, raw: dict[int, RunLog]):
    """Robot ``robot`` imported with a noise model fitted on the *other* robots of ``raw``:
    ``(header, records, model)``."""
    model = fit_noise_model([raw[j] for j in raw if j != robot])
    header, records = import_mrclam(folder, robot, model=model)
    return header, records, model


def robot_numbers(text: str) -> list[int]:
    """``"1,3"`` → ``[1, 3]`` (argparse ``type=``: anything else is a one-line usage error)."""
    try:
        return [int(r) for r in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: give robot numbers separated by commas, e.g. 1,3") from None


def add_dataset_arguments(parser: argparse.ArgumentParser) -> None:
    """The dataset folder and ``--robots`` (the MRCLAM scripts share them; :func:`chosen_robots`)."""
    parser.add_argument("folder", help="an MRCLAM_DatasetK folder")
    parser.add_argument("--robots", type=robot_numbers, default=list(ROBOT_SUBJECTS),
                        help="robots to score, comma separated (default all five)")


def chosen_robots(robots: list[int], raw: dict[int, RunLog]) -> list[int]:
    """The robots of ``robots`` (``--robots``, :func:`robot_numbers`) that the dataset has."""
    return [r for r in robots if r in raw]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_dataset_arguments(parser)
    parser.add_argument("--estimators", default="ekf,isam2,dead_reckoning", help="default ekf,isam2,dead_reckoning")
    parser.add_argument("--no-model", action="store_true", help="use the round default noise instead of a fitted model")
    parser.add_argument("--fit-on", type=robot_numbers, default=None, metavar="ROBOTS",
                        help="fit one model on these robots (comma separated) and score the others with it "
                             "(default: each robot with a model fitted on all the others)")
    parser.add_argument("--figure", default=None, metavar="PNG", help="write the trajectories over Vicon here")
    parser.add_argument("--json", default=None, metavar="FILE", help="write every figure (and the fitted models) here")
    args = parser.parse_args(argv)
    names = parse_estimator_names(args.estimators)
    raw = raw_logs(args.folder)
    robots = chosen_robots(args.robots, raw)
    shared = None
    if args.fit_on is not None:
        option = f"--fit-on {','.join(map(str, args.fit_on))}"
        if args.no_model:
            parser.error(f"{option} fits a model and --no-model scores without one: give one of them")
        fit_on = chosen_robots(args.fit_on, raw)
        robots = [k for k in robots if k not in fit_on]
        if not fit_on or not robots:
            parser.error(f"{option}: need at least one robot of {sorted(raw)} to fit on and one other to score")
        try:
            shared = fit_noise_model([raw[j] for j in fit_on])
        except NoiseModelError as exc:
            parser.error(f"{option}: {exc}")
    results, models = {}, {}
    for k in robots:
        if args.no_model:
            log = raw[k]
        else:
            if shared is None:
                header, records, model = leave_one_out(args.folder, k, raw)
            else:
                model = shared
                header, records = import_mrclam(args.folder, k, model=model)
            models[k] = model.to_dict()
            log = RunLog(f"{args.folder}/robot{k}", header, tuple(records))
        results[k] = score_robot(log, names, time_alone=True)
        print(f"robot {k}: " + ", ".join(f"{n} {results[k][n]['ate_final_m']:.3f} m" for n in names if n in results[k]),
              file=sys.stderr, flush=True)
    print_table(results, names)
    if args.figure:
        draw_figure(results, args.figure, names)
    if args.json:
        slim = {k: {n: {c: v for c, v in r.items() if c != "final"} for n, r in res.items() if n != "_truth"}
                for k, res in results.items()}
        Path(args.json).write_text(json.dumps({"results": slim, "models": models}, indent=1) + "\n")
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

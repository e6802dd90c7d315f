"""Which parameter of the noise learned without truth costs the most accuracy on MRCLAM.

For each robot k: the model learned from its own log without truth (what ``fgslam run LOG
--noise self`` fits) and the model fitted on the other robots' Vicon (leave-one-out,
``fgslam calibrate``). Each variant is the learned model with one part swapped for the
Vicon model's, applied to the round-number log (``slamio.noise.apply``) and scored against
Vicon: anchored / aligned ATE, NIS in band. Truth is the checker only: it never enters the
learned model. Variants: ``self``, ``vicon``, a part name or several joined by ``+`` (the
learned model with those parts from Vicon), ``learn:range`` / ``learn:range+scales`` (learned
without truth with the range model / and the odometry's scales; ``learn:range|PARTS`` with
PARTS from Vicon on top). Prints a markdown table of medians and each robot's figures;
caches the models as JSON in ``--cache``.

    PYTHONPATH=. .venv/bin/python -m scripts.experiments.selffit_diagnose RUNS_DIR [--variants a,b]

``RUNS_DIR`` holds ``robotN.jsonl`` imported with ``fgslam import mrclam FOLDER
RUNS_DIR/robotN.jsonl --robot N --noise round``.
"""

from __future__ import annotations

from scripts.common import one_blas_thread

one_blas_thread()

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import json  # noqa: E402
import os  # noqa: E402
import sys  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402

import numpy as np  # noqa: E402

from fgslam.compare.errors import nis_summary  # noqa: E402
from fgslam.runner import ESTIMATORS, run_estimator, truth_trajectory  # noqa: E402
from slamio.log import read_log  # noqa: E402
from slamio.noise.apply import apply_noise_model  # noqa: E402
from slamio.noise.model import NoiseModel, load_noise_model, save_noise_model  # noqa: E402

from scripts.bench_mrclam import ate_pair_m  # noqa: E402

ROBOTS = (1, 2, 3, 4, 5)
ODOMETRY_PARTS = {
    "lag": ("lag_s",), "forward_scale": ("forward_scale",), "turn_scale": ("turn_scale",),
    "turn_per_m": ("turn_per_m_rad",), "odometry_rates": ("noise",),
    "scales": ("forward_scale", "turn_scale", "turn_per_m_rad"),
    "odometry": ("lag_s", "forward_scale", "turn_scale", "turn_per_m_rad", "noise"),
}
OBSERVATION_PARTS = {
    "range_geometry": ("range_is_depth", "range_scale", "range_bias_m"),
    "range_depth": ("range_is_depth",), "range_bias": ("range_bias_m",), "range_depth_bias": ("range_is_depth", "range_bias_m"),
    "bearing_geometry": ("bearing_scale", "bearing_bias_rad"),
    "latency": ("camera_latency_s",),
    "reading_sigmas": ("range_sigma_m", "range_sigma_per_m", "bearing_sigma_rad", "bearing_sigma_s"),
    "outliers": ("outlier_rate",),
    "correlation": ("correlated_share", "correlation_time_s"),
    "mount": ("sensor_pose_on_robot",),
    "observation": ("range_is_depth", "range_scale", "range_bias_m", "bearing_scale", "bearing_bias_rad",
                    "camera_latency_s", "range_sigma_m", "range_sigma_per_m", "bearing_sigma_rad", "bearing_sigma_s",
                    "outlier_rate", "correlated_share", "correlation_time_s"),
}
DEFAULT_VARIANTS = ("self", "vicon") + tuple(ODOMETRY_PARTS) + tuple(OBSERVATION_PARTS)


def swapped(learned: NoiseModel, vicon: NoiseModel, parts: list[str]) -> NoiseModel:
    """``learned`` with the named parts taken from ``vicon``."""
    odo = {f: getattr(vicon.odometry, f) for p in parts if p in ODOMETRY_PARTS for f in ODOMETRY_PARTS[p]}
    obs = {f: getattr(vicon.observation, f) for p in parts if p in OBSERVATION_PARTS for f in OBSERVATION_PARTS[p]}
    return dataclasses.replace(learned, odometry=dataclasses.replace(learned.odometry, **odo),
                               observation=dataclasses.replace(learned.observation, **obs))


def models(runs: str, cache: str, k: int) -> tuple[NoiseModel, NoiseModel]:
    """(learned without truth on robot k, Vicon-fitted on the others), cached."""
    from fgslam.self_calibration import fit_without_truth
    from slamio.noise.fit_truth import fit_noise_model

    self_path, vicon_path = os.path.join(cache, f"self{k}.json"), os.path.join(cache, f"vicon_loo{k}.json")
    if not os.path.exists(self_path):
        save_noise_model(self_path, fit_without_truth([read_log(os.path.join(runs, f"robot{k}.jsonl"))]).model)
    if not os.path.exists(vicon_path):
        others = [read_log(os.path.join(runs, f"robot{j}.jsonl")) for j in ROBOTS if j != k]
        save_noise_model(vicon_path, fit_noise_model(others))
    return load_noise_model(self_path), load_noise_model(vicon_path)


def own_vicon(runs: str, cache: str, k: int) -> NoiseModel:
    """The model fitted on robot k's own Vicon (what perfect trials would tell of it), cached."""
    from slamio.noise.fit_truth import fit_noise_model

    path = os.path.join(cache, f"vicon_own{k}.json")
    if not os.path.exists(path):
        save_noise_model(path, fit_noise_model([read_log(os.path.join(runs, f"robot{k}.jsonl"))]))
    return load_noise_model(path)


def learned_with(runs: str, cache: str, k: int, what: list[str]) -> NoiseModel:
    """Learned without truth with the extra parts ``what`` (``range``: the camera's range
    model; ``scales``: the odometry's scales; ``pin``: the forward and turn scales and the
    turn per metre pinned at robot k's own Vicon fit, as trials would), cached."""
    from fgslam.self_calibration import fit_without_truth

    path = os.path.join(cache, f"learn{k}_{'+'.join(what)}.json")
    if not os.path.exists(path):
        log = read_log(os.path.join(runs, f"robot{k}.jsonl"))
        pinned = None
        if "pin" in what:
            odometry = own_vicon(runs, cache, k).odometry
            pinned = {name: getattr(odometry, name) for name in ("forward_scale", "turn_scale", "turn_per_m_rad")}
        save_noise_model(path, fit_without_truth([log], range_model="range" in what, scales="scales" in what,
                                                 pinned=pinned).model)
    return load_noise_model(path)


def variant_model(runs: str, cache: str, k: int, variant: str) -> NoiseModel:
    learned, vicon = models(runs, cache, k)
    if variant == "self":
        return learned
    if variant == "vicon":
        return vicon
    if variant.startswith("learn:"):  # learn:WHAT or learn:WHAT|PARTS (PARTS swapped for Vicon's)
        what, _, parts = variant[len("learn:"):].partition("|")
        model = learned_with(runs, cache, k, what.split("+"))
        return swapped(model, vicon, parts.split("+")) if parts else model
    if variant.startswith("file:"):
        return load_noise_model(variant[len("file:"):].replace("{k}", str(k)))
    return swapped(learned, vicon, variant.split("+"))


def score(log, model: NoiseModel) -> dict:
    log, _ = apply_noise_model(log, model)
    steps = log.steps()
    truth, mask = truth_trajectory(steps)
    truth = truth[:, :2]
    out = {}
    for name in ("ekf", "isam2"):
        run, _ = run_estimator(ESTIMATORS[name](log.header), steps, covariances=True)
        out[name] = ate_pair_m(run.final, truth, mask) + ate_pair_m(run.online, truth, mask) + \
            (nis_summary(run.nis, run.nis_dofs)[1],)
    return out


def one(args) -> tuple[int, str, dict]:
    runs, cache, k, variant = args
    model = variant_model(runs, cache, k, variant)
    return k, variant, score(read_log(os.path.join(runs, f"robot{k}.jsonl")), model)


COLUMNS = (("EKF", "ekf", 0, 1), ("iSAM2 final", "isam2", 0, 1), ("iSAM2 online", "isam2", 2, 3))


def row(label: str, results: dict) -> str:
    cells = []
    for _, name, a, b in COLUMNS:
        cells.append(f"{results[name][a]:.3f} / {results[name][b]:.3f}")
    cells.append(f"{100 * results['ekf'][4]:.1f} / {100 * results['isam2'][4]:.1f}")
    return f"| {label} | " + " | ".join(cells) + " |"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("runs")
    parser.add_argument("--cache", default=None, help="where the models are kept (default RUNS/models)")
    parser.add_argument("--variants", default=",".join(DEFAULT_VARIANTS))
    parser.add_argument("--robots", default=",".join(map(str, ROBOTS)))
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--json", default=None, help="also write every figure here")
    args = parser.parse_args(argv)
    cache = args.cache or os.path.join(args.runs, "models")
    os.makedirs(cache, exist_ok=True)
    robots = [int(v) for v in args.robots.split(",")]
    variants = args.variants.split(",")
    with ProcessPoolExecutor(args.jobs) as pool:  # the models first, once per robot
        list(pool.map(models, [args.runs] * len(robots), [cache] * len(robots), robots))
        done = list(pool.map(one, [(args.runs, cache, k, v) for v in variants for k in robots]))
    table = {v: {k: r for k, vv, r in done if vv == v} for v in variants}
    print("| variant | EKF anchored / aligned | iSAM2 final | iSAM2 online | NIS in band % EKF / iSAM2 |")
    print("|---|---|---|---|---|")
    for v in variants:
        med = {name: [float(np.median([table[v][k][name][i] for k in robots])) for i in range(5)]
               for name in ("ekf", "isam2")}
        print(row(f"{v} (median)", med))
    print()
    for v in variants:
        for k in robots:
            print(row(f"{v} robot {k}", table[v][k]))
    if args.json:
        with open(args.json, "w") as f:
            json.dump({v: {str(k): r for k, r in t.items()} for v, t in table.items()}, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Every seed-003 estimator on the seed's real drives and on simulated drives: tables + top views.

    python -m scripts.seed003_drives [--data /work/shared/data/seed003] [--seeds 1-10] [--out docs]
    python -m scripts.seed003_drives --scaling      # time per step as the map grows

For each drive: ``ekf-s003`` as written and with its typos read as the paper's figures
require (``AS_THE_FIGURES_SHOW``; its pose is the IMU dead reckoning), ``ekf-vio``,
``ekf-vio-fej`` (the same with first-estimate Jacobians),
``isam2-vio`` (online trajectory) and ``batch`` (LM on the same graph, the reference where
there is no truth). Prints markdown tables: ATE 3-D and top-view 2-D against truth
(simulated) or against the batch solution (real), median landmark error, mean time per
step; then the cost of each seed-003 flaw. Writes ``seed003_<drive>.png`` top views.
The real drives (KITTI-derived, CC BY-NC-SA) are read from ``--data``, never copied.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from scripts.common import one_blas_thread

one_blas_thread(force=False)

import numpy as np  # noqa: E402

from ekf.drive3d import position_errors_m, steps_of  # noqa: E402
from ekf.stereo_imu_ekf import AS_THE_FIGURES_SHOW, EkfS003  # noqa: E402
from ekf.vio import VioEkf  # noqa: E402
from fgslam.smoother3d import StereoIsam2, batch_solve  # noqa: E402
from slamio.datasets.seed003 import load_drive  # noqa: E402
from slamio.sim3d import simulate_drive  # noqa: E402
from scripts.common import SHARED_DATA, parse_seeds  # noqa: E402

FLAW_VARIANTS = {
    "as written": {},
    "eq. 16 read as exp(−τû)μ": {"eq16_literal": False},
    "eq. 1 rows in M's order": {"stereo_rows": "matrix"},
    "both typos read as intended (figures)": AS_THE_FIGURES_SHOW,
    "figures + eq. 11 as printed": dict(AS_THE_FIGURES_SHOW, covariance_update="eq11"),
    "figures + V = 3000 as process noise": dict(AS_THE_FIGURES_SHOW, v_role="process"),
}


def timed_run(estimator, drive):
    seconds = []
    for args in steps_of(drive):
        start = time.perf_counter()
        estimator.step(*args)
        seconds.append(time.perf_counter() - start)
    return estimator, float(np.mean(seconds))


def map_error_m(landmarks: dict, reference: dict) -> float:
    common = [j for j in landmarks if j in reference]
    if not common:
        return float("nan")
    return float(np.median([np.linalg.norm(landmarks[j] - reference[j]) for j in common]))


def run_all(drive):
    """{name: (trajectory, landmarks, ms per step)} and the batch result."""
    out = {}
    for name, make in (
        ("ekf-s003 as written", lambda: EkfS003(drive.K, drive.baseline_m, drive.cam_T_imu)),
        ("ekf-s003 figures' reading (= IMU dead reckoning)", lambda: EkfS003(drive.K, drive.baseline_m, drive.cam_T_imu, **AS_THE_FIGURES_SHOW)),
        ("ekf-vio", lambda: VioEkf(drive.K, drive.baseline_m, drive.cam_T_imu)),
        ("ekf-vio-fej", lambda: VioEkf(drive.K, drive.baseline_m, drive.cam_T_imu, first_estimates=True)),
    ):
        est, sec = timed_run(make(), drive)
        out[name] = (est.trajectory(), est.landmarks(), 1e3 * sec)
    smoother, sec = timed_run(StereoIsam2(drive.K, drive.baseline_m, drive.cam_T_imu), drive)
    out["isam2-vio (online)"] = (smoother.trajectory(), smoother.landmarks(), 1e3 * sec)
    smoother.finish()
    batch = batch_solve(smoother)
    out["batch (LM)"] = (batch.trajectory(), batch.landmarks(), float("nan"))
    return out, smoother, batch


def reference_of(drive, batch):
    if drive.truth_world_T_imu is not None:
        return drive.truth_world_T_imu, {j: drive.truth_landmarks_m[j] for j in range(drive.n_landmarks)}, "truth"
    return batch.trajectory(), batch.landmarks(), "batch"


def top_view(path, title, results, drive, reference_name):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(13, 5.5))
    traj, lms, _ = results["ekf-s003 figures' reading (= IMU dead reckoning)"]
    pts = np.array(list(lms.values())) if lms else np.zeros((0, 3))
    left.scatter(pts[:, 0], pts[:, 1], s=3, c="tab:blue", label="landmarks")
    left.plot(traj[:, 0, 3], traj[:, 1, 3], "r-", lw=1.5, label="trajectory")
    left.set_title("ekf-s003, typos read as intended (the seed's figure)")
    styles = {
        "ekf-s003 as written": ("tab:orange", ":"),
        "ekf-s003 figures' reading (= IMU dead reckoning)": ("tab:red", "--"),
        "ekf-vio": ("tab:green", "-"),
        "ekf-vio-fej": ("tab:olive", "-."),
        "isam2-vio (online)": ("tab:purple", "-"),
        "batch (LM)": ("k", "-"),
    }
    b_pts = np.array(list(results["batch (LM)"][1].values()))
    right.scatter(b_pts[:, 0], b_pts[:, 1], s=3, c="0.6", label="batch landmarks")
    if drive.truth_world_T_imu is not None:
        t = drive.truth_world_T_imu
        right.plot(t[:, 0, 3], t[:, 1, 3], color="tab:cyan", lw=3, alpha=0.5, label="truth")
    for name, (colour, style) in styles.items():
        tr = results[name][0]
        right.plot(tr[:, 0, 3], tr[:, 1, 3], color=colour, ls=style, lw=1.2, label=name)
    right.set_title(f"all estimators (reference: {reference_name})")
    for ax in (left, right):
        ax.set_aspect("equal", adjustable="box")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.legend(fontsize=7, loc="best")
        ax.plot([0], [0], "k^", ms=8)
    # frame the trajectories (a few far landmarks would otherwise shrink the drive to a line)
    all_xy = np.vstack([results[n][0][:, :2, 3] for n in styles if n != "ekf-s003 as written"])
    lo, hi = all_xy.min(axis=0), all_xy.max(axis=0)
    margin = 0.15 * float(np.max(hi - lo)) + 20.0
    for ax in (left, right):
        ax.set_xlim(lo[0] - margin, hi[0] + margin)
        ax.set_ylim(lo[1] - margin, hi[1] + margin)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def flaw_costs(drive, ref_traj, ref_landmarks):
    rows = {}
    for name, kw in FLAW_VARIANTS.items():
        est, _ = timed_run(EkfS003(drive.K, drive.baseline_m, drive.cam_T_imu, **kw), drive)
        rows[name] = (position_errors_m(est.trajectory(), ref_traj)[0], map_error_m(est.landmarks(), ref_landmarks))
    return rows


def scaling(seed: int = 1) -> None:
    """ms per step of ekf-vio and isam2-vio against the number of landmarks mapped so far,
    on one large simulated drive (a 0.9 km loop, about 1 000 landmarks)."""
    from slamio.sim3d import DriveScenario

    drive = simulate_drive(seed, DriveScenario(straight_m=300.0, side_m=120.0))
    estimators = {
        "ekf-vio": VioEkf(drive.K, drive.baseline_m, drive.cam_T_imu),
        "isam2-vio": StereoIsam2(drive.K, drive.baseline_m, drive.cam_T_imu),
    }
    counts, seconds = {n: [] for n in estimators}, {n: [] for n in estimators}
    for args in steps_of(drive):
        for name, est in estimators.items():
            start = time.perf_counter()
            est.step(*args)
            seconds[name].append(time.perf_counter() - start)
            counts[name].append(est.landmarks_added)
    print(f"Time per step against landmarks mapped ({drive.n_steps} steps, {drive.n_landmarks} landmarks in the world):\n")
    print("| landmarks mapped | ekf-vio ms/step | isam2-vio ms/step |")
    print("|---|---|---|")
    n = np.array(counts["ekf-vio"])
    edges = [0, 100, 200, 400, 600, 800, 1000, 1200, 10**6]
    for lo, hi in zip(edges[:-1], edges[1:]):
        sel = (n >= lo) & (n < hi)
        if sel.any():
            ekf_ms = 1e3 * np.median(np.array(seconds["ekf-vio"])[sel])
            isam_ms = 1e3 * np.median(np.array(seconds["isam2-vio"])[sel])
            print(f"| {lo}–{min(hi, int(n.max()))} | {ekf_ms:.1f} | {isam_ms:.1f} |")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=str(SHARED_DATA / "seed003"))
    parser.add_argument("--seeds", default="1-10")
    parser.add_argument("--out", default="docs")
    parser.add_argument("--scaling", action="store_true", help="only the time-per-step table on a large simulated drive")
    args = parser.parse_args(argv)
    if args.scaling:
        scaling()
        return 0
    out_dir = Path(args.out)

    drives = [(p.stem, load_drive(p)) for p in sorted(Path(args.data).glob("*.npz"))]
    drives += [(f"sim{seed}", simulate_drive(seed)) for seed in parse_seeds(args.seeds)]

    print("| drive | steps | landmarks | estimator | ATE 3-D m | ATE 2-D m | map median m | ms/step | reference |")
    print("|---|---|---|---|---|---|---|---|---|")
    sim_ate: dict[str, list] = {}
    flaw_rows: dict[str, dict] = {}
    consistency = []
    for name, drive in drives:
        results, smoother, batch = run_all(drive)
        ref_traj, ref_lms, ref_name = reference_of(drive, batch)
        for est_name, (traj, lms, ms) in results.items():
            a3, a2 = position_errors_m(traj, ref_traj)
            if ref_name == "batch" and est_name == "batch (LM)":
                a3 = a2 = 0.0
            print(f"| {name} | {drive.n_steps} | {drive.n_landmarks} | {est_name} | {a3:.3f} | {a2:.3f} | {map_error_m(lms, ref_lms):.3f} | {ms:.2f} | {ref_name} |")
            if ref_name == "truth":
                sim_ate.setdefault(est_name, []).append((a3, a2, map_error_m(lms, ref_lms), ms))
        consistency.append((name, smoother.error(), batch.error, smoother.stereo_factors, batch.seconds))
        flaw_rows[name] = flaw_costs(drive, ref_traj, ref_lms)
        if not name.startswith("sim") or name == "sim1":
            top_view(out_dir / f"seed003_{name}.png", f"seed 003 drive {name}", results, drive, ref_name)
        sys.stdout.flush()

    if sim_ate:
        print("\nMean over the simulated drives (against truth):\n")
        print("| estimator | ATE 3-D m | ATE 2-D m | map median m | ms/step |")
        print("|---|---|---|---|---|")
        for est_name, rows in sim_ate.items():
            a = np.array(rows)
            print(f"| {est_name} | {a[:, 0].mean():.3f} | {a[:, 1].mean():.3f} | {np.nanmean(a[:, 2]):.3f} | {a[:, 3].mean():.2f} |")

    print("\niSAM2 (after finish) vs batch LM, graph error ½Σρ(r):\n")
    print("| drive | stereo factors | iSAM2 | batch | difference | batch s |")
    print("|---|---|---|---|---|---|")
    for name, e_isam, e_batch, n_f, secs in consistency:
        print(f"| {name} | {n_f} | {e_isam:.1f} | {e_batch:.1f} | {100 * (e_isam - e_batch) / e_batch:+.3f} % | {secs:.1f} |")

    print("\nCost of each seed-003 flaw (pose ATE 3-D m / median map error m; real drives against batch):\n")
    names = [n for n, _ in drives if not n.startswith("sim")]
    sims = [n for n, _ in drives if n.startswith("sim")]
    header = "| setting | " + " | ".join(names) + (f" | simulated (mean of {len(sims)}) |" if sims else " |")
    print(header)
    print("|" + "---|" * (header.count("|") - 1))
    for variant in FLAW_VARIANTS:
        cells = [f"{flaw_rows[n][variant][0]:.1f} / {flaw_rows[n][variant][1]:.1f}" for n in names]
        if sims:
            a = np.array([flaw_rows[n][variant] for n in sims])
            cells.append(f"{a[:, 0].mean():.2f} / {np.nanmean(a[:, 1]):.2f}")
        print(f"| {variant} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())

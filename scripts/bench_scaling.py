"""Benchmark: per-step cost and accuracy of EKF-SLAM vs iSAM2 as the map grows.

For each N in ``--sizes`` (default 100 500 1000 2000) simulate ``fgslam sim grid
--landmarks N`` (seed ``--seed``), run the EKF and each iSAM2 configuration of
``--isam2`` (default: ``isam2`` and the batched preset ``isam2-fast``) in this one
process, and print per-step p50/p99/mean time (mean = total including ``finish()`` over
the steps), total time, ATE against the simulator's truth (final and online), and the
ratios EKF/iSAM2.
``--laps`` overrides the scenario's lap count (``--laps 1`` keeps N >= 1000 tractable:
the EKF is O(N^2) per step). ``--plot PATH`` writes a PNG of time per step vs N.

OPENBLAS_NUM_THREADS is forced to 1 before numpy loads (shared machine).
"""

from __future__ import annotations

from scripts.common import one_blas_thread

one_blas_thread()

import argparse  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from ekf import EkfSlam  # noqa: E402
from fgslam.compare import ate_rmse_m  # noqa: E402
from fgslam.runner import run_estimator  # noqa: E402
from fgslam.runner import ESTIMATORS  # noqa: E402
from slamio.log import group_steps  # noqa: E402
from slamio.sim import simulate  # noqa: E402
from scripts.common import step_ms as ms  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[100, 500, 1000, 2000])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--laps", type=int, default=None, help="laps of the grid (default: the scenario's)")
    ap.add_argument("--plot", type=Path, default=None, help="write a PNG of time per step vs N here")
    ap.add_argument("--isam2", nargs="+", default=["isam2", "isam2-fast"],
                    choices=[n for n in ESTIMATORS if n.startswith("isam2")],
                    help="iSAM2 configurations to compare with the EKF (default: isam2 isam2-fast)")
    args = ap.parse_args(argv)

    names = ["ekf"] + list(dict.fromkeys(args.isam2))
    results: dict[str, list[tuple[int, float, float, float]]] = {name: [] for name in names}
    print(f"{'N':>5} {'steps':>6} {'estimator':>10} {'p50 ms':>8} {'p99 ms':>8} {'mean ms':>8} {'total s':>8} "
          f"{'ATE m':>7} {'online':>7}")
    for n in args.sizes:
        header, records = simulate("grid", args.seed, landmarks=n, laps=args.laps)
        steps = group_steps(header, records)
        truth = np.array([[s.truth.x_m, s.truth.y_m, s.truth.theta_rad] for s in steps])
        runs = {}
        for name in names:
            run, _ = run_estimator(EkfSlam(header) if name == "ekf" else ESTIMATORS[name](header), steps,
                                   covariances=False)
            runs[name] = run
            mean_ms = 1e3 * run.total_time_s / len(steps)
            results[name].append((n, ms(run, 50), ms(run, 99), mean_ms))
            print(f"{n:5d} {len(steps):6d} {name:>10} {ms(run, 50):8.3f} {ms(run, 99):8.2f} {mean_ms:8.3f} "
                  f"{run.total_time_s:8.2f} {ate_rmse_m(run.final, truth):7.3f} {ate_rmse_m(run.online, truth):7.3f}",
                  flush=True)
        e = runs["ekf"]
        for name in names[1:]:
            i = runs[name]
            print(f"{'':5} EKF/{name}: per-step p50 {ms(e, 50) / ms(i, 50):.1f}x, p99 {ms(e, 99) / ms(i, 99):.1f}x, "
                  f"mean (total incl. finish) {e.total_time_s / i.total_time_s:.1f}x; ATE {name}/EKF final "
                  f"{ate_rmse_m(i.final, truth) / ate_rmse_m(e.final, truth):.2f}, online "
                  f"{ate_rmse_m(i.online, truth) / ate_rmse_m(e.online, truth):.2f}", flush=True)

    if args.plot is not None:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(6.5, 4.2))
        for name, marker in zip(names, "osd^v"):
            a = np.array(results[name])
            (line,) = ax.loglog(a[:, 0], a[:, 1], marker + "-", label=f"{name} p50")
            ax.loglog(a[:, 0], a[:, 3], marker + ":", color=line.get_color(), label=f"{name} mean")
            ax.loglog(a[:, 0], a[:, 2], marker + "--", color=line.get_color(), alpha=0.5, label=f"{name} p99")
        ax.set_xlabel("landmarks N (grid scenario, seed %d)" % args.seed)
        ax.set_ylabel("time per step (ms)")
        ax.legend(fontsize=7, ncol=2)
        ax.grid(True, which="both", alpha=0.3)
        fig.tight_layout()
        fig.savefig(args.plot, dpi=120)
        print(f"wrote {args.plot}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

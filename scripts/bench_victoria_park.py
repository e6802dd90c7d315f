"""Benchmark: EKF-SLAM vs iSAM2 vs batch LM on Victoria Park, in one process.

    OPENBLAS_NUM_THREADS is forced to 1 before numpy loads (a shared machine: multithreaded
    BLAS made single iSAM2 updates ~20x slower under load).

Usage::

    .venv/bin/python -m scripts.bench_victoria_park                  # the isam2-fast preset
    .venv/bin/python -m scripts.bench_victoria_park --preset default # Isam2Smoother() as is
    .venv/bin/python -m scripts.bench_victoria_park --set relinearize_skip=5 ...
    .venv/bin/python -m scripts.bench_victoria_park --sweep          # the knob table of docs/performance.md

Prints total time, per-step p50/p99 for EKF and iSAM2, the batch solve's time, χ²/2 of
iSAM2's final estimate and of the batch optimum (LM seeded from iSAM2), and the ratios
iSAM2/EKF time and iSAM2 χ² / batch χ². ``--set key=value`` overrides Isam2Smoother
keyword arguments of the preset; ``--no-ekf`` skips the EKF. ``--sweep`` runs the EKF once
and then a fixed list of iSAM2 settings, printing one markdown table row each.
"""

from __future__ import annotations

from scripts.common import one_blas_thread

one_blas_thread()

import argparse  # noqa: E402

from ekf import EkfSlam  # noqa: E402
from fgslam.compare import ate_rmse_m  # noqa: E402
from fgslam.runner import run_estimator  # noqa: E402
from fgslam.smoother import FAST_SETTINGS, Isam2Smoother, batch_solve  # noqa: E402
from slamio.datasets.victoria_park import import_victoria_park  # noqa: E402
from slamio.log import group_steps  # noqa: E402
from scripts.common import parse_assignments as parse_sets, step_ms as ms  # noqa: E402

PRESETS = {"fast": FAST_SETTINGS, "default": {}}

#: (label, Isam2Smoother keywords) for ``--sweep``: one knob at a time, from the defaults
#: to the isam2-fast preset.
SWEEP = [
    ("defaults (0.01/10, every step)", {}),
    ("GTSAM's 0.1/10, every step", {"relinearize_threshold": 0.1}),
    ("0.1/10, `update_on=observations`", {"relinearize_threshold": 0.1, "update_on": "observations"}),
    ("0.1/10, obs, `update_every=10`", {"relinearize_threshold": 0.1, "update_on": "observations", "update_every": 10}),
    ("0.1/10, obs, `update_every=50`", {"relinearize_threshold": 0.1, "update_on": "observations", "update_every": 50}),
    ("(1 m, 0.05 rad)/10, obs, every 50",
     {**FAST_SETTINGS, "relinearize_skip": 10, "wildfire_threshold": 0.001, "keyframes": False}),
    ("same, skip 20", {**FAST_SETTINGS, "wildfire_threshold": 0.001, "keyframes": False}),
    ("same, wildfire 1.0", {**FAST_SETTINGS, "keyframes": False}),
    ("same, keyframes = **isam2-fast**", dict(FAST_SETTINGS)),
    ("isam2-fast, `final_iterations=0`", {**FAST_SETTINGS, "final_iterations": 0}),
    ("isam2-fast, `update_every=100`", {**FAST_SETTINGS, "update_every": 100, "max_held_steps": 100}),
]


def _run_isam2(kwargs: dict):
    """One iSAM2 run on Victoria Park, in a fresh process (see :func:`sweep`)."""
    header, records = import_victoria_park()
    run, smoother = run_estimator(Isam2Smoother(header, **kwargs), group_steps(header, records), covariances=False)
    return run, smoother.updates, smoother.error()


def sweep(header, steps, ekf) -> None:
    """One markdown row per SWEEP setting. Each runs in a fresh process: run one after another
    in one process, later smoothers were up to 30 % slower than alone."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    print(f"\nEKF: {ekf.total_time_s:.2f} s total, p50 {ms(ekf, 50):.3f} ms, p99 {ms(ekf, 99):.2f} ms\n")
    print("| settings | total s | × EKF | p50 / p99 ms | updates | χ²/2 final | × batch | online ATE m |")
    print("|---|---|---|---|---|---|---|---|")
    batch = batch_solve(run_estimator(Isam2Smoother(header), steps, covariances=False)[1])  # the optimum, once
    context = multiprocessing.get_context("spawn")
    for label, kwargs in SWEEP:
        with ProcessPoolExecutor(max_workers=1, mp_context=context) as pool:
            run, updates, chi2 = pool.submit(_run_isam2, kwargs).result()
        print(f"| {label} | {run.total_time_s:.2f} | {run.total_time_s / ekf.total_time_s:.2f} | "
              f"{ms(run, 50):.3f} / {ms(run, 99):.1f} | {updates} | {chi2:.2f} | "
              f"{chi2 / batch.final_error:.5f} | {ate_rmse_m(run.online, batch.trajectory):.2f} |", flush=True)
    print(f"\nbatch optimum χ²/2 {batch.final_error:.2f}; EKF online ATE vs it "
          f"{ate_rmse_m(ekf.online, batch.trajectory):.2f} m")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", choices=sorted(PRESETS), default="fast",
                    help="fast: the isam2-fast preset (default); default: Isam2Smoother's defaults")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="Isam2Smoother keyword")
    ap.add_argument("--no-ekf", action="store_true", help="skip the EKF (knob sweeps)")
    ap.add_argument("--sweep", action="store_true", help="print the knob table of docs/performance.md")
    args = ap.parse_args(argv)
    kwargs = {**PRESETS[args.preset], **parse_sets(args.set)}

    header, records = import_victoria_park()
    steps = group_steps(header, records)
    print(f"Victoria Park: {len(steps)} steps, {sum(len(s.observations) for s in steps)} observations")

    ekf = None
    if not args.no_ekf:
        ekf, _ = run_estimator(EkfSlam(header), steps, covariances=False)
    if args.sweep:
        if ekf is None:
            ap.error("--sweep needs the EKF (drop --no-ekf)")
        sweep(header, steps, ekf)
        return 0

    print(f"Isam2Smoother kwargs: {kwargs or '(defaults)'}")
    isam, smoother = run_estimator(Isam2Smoother(header, **kwargs), steps, covariances=False)
    isam_chi2 = smoother.error()
    batch = batch_solve(smoother)

    rows = [("isam2", isam)] + ([("ekf", ekf)] if ekf is not None else [])
    print(f"{'':8}{'total s':>9}{'p50 ms':>9}{'p99 ms':>9}{'max ms':>9}")
    for name, run in rows:
        print(f"{name:8}{run.total_time_s:9.2f}{ms(run, 50):9.3f}{ms(run, 99):9.2f}{ms(run, 100):9.1f}")
    print(f"{'batch':8}{batch.time_s:9.2f}   ({batch.iterations} LM iterations from iSAM2's estimate)")
    print(f"iSAM2 updates: {smoother.updates}, final Gauss-Newton steps: {smoother.final_iterations_run}, "
          f"update failures: {smoother.update_failures}")
    print(f"chi2/2: iSAM2 final {isam_chi2:.2f}, batch {batch.final_error:.2f}")
    print(f"ATE vs batch: iSAM2 final {ate_rmse_m(isam.final, batch.trajectory):.3f} m, "
          f"iSAM2 online {ate_rmse_m(isam.online, batch.trajectory):.3f} m"
          + (f", EKF online {ate_rmse_m(ekf.online, batch.trajectory):.3f} m" if ekf is not None else ""))
    print("ratios:")
    print(f"  iSAM2 chi2 / batch chi2   = {isam_chi2 / batch.final_error:.5f}   (goal <= 1.01)")
    if ekf is not None:
        print(f"  iSAM2 time / EKF time     = {isam.total_time_s / ekf.total_time_s:.2f}   (goal <= 1.5)")
        print(f"  batch time / EKF time     = {batch.time_s / ekf.total_time_s:.3f}")
    print(f"  batch time / iSAM2 time   = {batch.time_s / isam.total_time_s:.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

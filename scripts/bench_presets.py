"""Benchmark: accuracy per CPU second — every planar iSAM2 preset and the EKF as points.

Issue 43's stretch goal: for each log, the total CPU time of each estimator's run (the
steps and ``finish()``, no NEES/NIS, as ``fgslam run --no-consistency`` times them) against
its online ATE (against the log's truth where it has it, else the batch optimum), and
whether some preset costs at most the EKF's time with an online ATE no worse than the
EKF's on every log. One process, BLAS on one thread, each run ``--repeats`` times
interleaved (the least CPU time is kept: CPU time is less disturbed by a busy machine than
wall time, not immune to it). Prints a table per log and a last verdict per preset;
``--figure PNG`` draws one panel per log (time × EKF on x, online ATE on y).

Usage::

    .venv/bin/python -m scripts.bench_presets victoria-park plaza1 \\
        mrclam:../shared/data/mrclam/MRCLAM_Dataset6:1,2,3,4,5 --figure docs/presets.png

Log sources are those of ``scripts/bench_online.py``.
"""

from __future__ import annotations

from scripts.common import one_blas_thread

one_blas_thread()

import argparse  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402

from scripts.bench_online import logs, online_ate_m, truth_of  # noqa: E402
from fgslam.registry import REGISTRY, build  # noqa: E402
from fgslam.runner import run_estimator  # noqa: E402
from fgslam.smoother import batch_solve  # noqa: E402
from slamio.log import group_steps  # noqa: E402


def planar_presets() -> list[str]:
    """Every planar iSAM2 estimator of the registry (``isam2``, ``isam2-fast``, the robust kernels…)."""
    return [name for name, e in REGISTRY.items() if e.isam2 and e.dimension == 2]


def timed_run(name: str, header, steps):
    """(run, estimator, CPU seconds) of one estimator over the steps."""
    estimator = build(name, 2, header)
    cpu = time.process_time()
    run, estimator = run_estimator(estimator, steps, covariances=False)
    return run, estimator, time.process_time() - cpu


def measure_log(header, records, names: list[str], repeats: int) -> dict[str, tuple[float, float]]:
    """{estimator: (least CPU seconds, online ATE m)}; ``"ekf"`` included."""
    steps = group_steps(header, records)
    truth = truth_of(steps)
    cpu = {name: [] for name in ["ekf", *names]}
    runs = {}
    batch = None
    for _ in range(repeats):
        for name in cpu:
            run, estimator, seconds = timed_run(name, header, steps)
            cpu[name].append(seconds)
            runs[name] = run
            if batch is None and name == "isam2":
                batch = batch_solve(estimator).trajectory
    out = {}
    for name, seconds in cpu.items():
        online = runs[name].online
        ate = online_ate_m(online, truth, batch) if online is not None else math.nan
        out[name] = (min(seconds), ate)
    return out


def verdict(results: dict[str, dict[str, tuple[float, float]]]) -> dict[str, bool]:
    """Per preset: at most the EKF's CPU time and no worse online ATE on every log."""
    names = {n for r in results.values() for n in r if n != "ekf"}
    return {n: all(r[n][0] <= r["ekf"][0] and r[n][1] <= r["ekf"][1] for r in results.values()) for n in sorted(names)}


def draw(results: dict, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FormatStrFormatter

    n = len(results)
    cols = min(n, 4)
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.6 * cols, 3.2 * rows), squeeze=False)
    for ax, (log, r) in zip(axes.flat, results.items()):
        ekf_cpu, ekf_ate = r["ekf"]
        for name, (cpu, ate) in r.items():
            ax.scatter(cpu / ekf_cpu, ate, marker="s" if name == "ekf" else "o", color="k" if name == "ekf" else None,
                       label=name)
        ax.set_xscale("log")  # a preset that fails on a log can cost 100× the EKF and err 10× more
        ax.set_yscale("log")
        for axis, values in ((ax.xaxis, [c / ekf_cpu for c, _ in r.values()]), (ax.yaxis, [a for _, a in r.values()])):
            axis.set_major_formatter(FormatStrFormatter("%g"))  # minor ticks named within one decade only
            axis.set_minor_formatter(FormatStrFormatter("%g" if max(values) < 10 * min(values) else ""))
        ax.axvline(1.0, color="grey", lw=0.6)
        ax.axhline(ekf_ate, color="grey", lw=0.6)
        ax.set_title(log, fontsize=8)
        ax.set_xlabel("CPU time × EKF (log scale)", fontsize=8)
        ax.set_ylabel("online ATE m (log scale)", fontsize=8)
        ax.tick_params(labelsize=7)
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=min(len(labels), 5), fontsize=7)
    fig.tight_layout(rect=(0, 0.08, 1, 1))
    fig.savefig(path, dpi=110)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="+", help="log sources, as scripts/bench_online.py takes them")
    ap.add_argument("--presets", default=None, help="comma-separated iSAM2 estimators (default: every planar one)")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--figure", default=None, metavar="PNG")
    args = ap.parse_args(argv)
    names = args.presets.split(",") if args.presets else planar_presets()
    results = {}
    for spec in args.logs:
        for log, header, records in logs(spec):
            r = results[log] = measure_log(header, records, names, args.repeats)
            ekf_cpu, ekf_ate = r["ekf"]
            print(f"\n## {log}: EKF {ekf_cpu:.2f} CPU s, online ATE {ekf_ate:.4f} m")
            print("| estimator | CPU s | × EKF | online ATE m | × EKF |")
            print("|---|---|---|---|---|")
            for name, (cpu, ate) in r.items():
                print(f"| {name} | {cpu:.2f} | {cpu / ekf_cpu:.2f} | {ate:.4f} | {ate / ekf_ate:.2f} |")
    print("\n## at most the EKF's CPU time, with no worse online ATE, on every log")
    for name, ok in verdict(results).items():
        print(f"- {name}: {'yes' if ok else 'no'}")
    if args.figure:
        draw(results, args.figure)
        print(f"wrote {args.figure}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

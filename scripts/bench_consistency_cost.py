"""Benchmark: the CPU cost of ``fgslam run``'s NEES/NIS work, every step against the sample.

For each log this runs ``fgslam run``'s default planar estimators as ``compare_log`` runs them
(:func:`fgslam.runner.run_estimator`, BLAS on one thread) with no consistency work, with it at
every step (``--consistency all``) and at the seeded sample (the default,
:mod:`fgslam.consistency_sample`), interleaved, ``--repeats`` times. It prints, by CPU time
(``time.thread_time``, the machine being shared): the estimators' own steps in each mode, the
consistency work in each mode (the NIS before the steps, the covariance after them, and the
landmark covariances after the run, for the map's ellipses: also shown alone) and its share of
the estimators' own time; then, the honesty
test, each estimator's NEES and NIS in-band shares over every step and over the sample, with
the sample's binomial standard error and the difference in standard errors.

Usage::

    PYTHONPATH=. .venv/bin/python -m scripts.bench_consistency_cost vp.jsonl p1.jsonl r1.jsonl ...
"""

from __future__ import annotations

from scripts.common import one_blas_thread, print_table_head, print_table_row

one_blas_thread()

import argparse  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from fgslam.compare import chi2_summary, nis_summary  # noqa: E402
from fgslam.compare.errors import in_band_se_by_step  # noqa: E402
from fgslam.compare.metrics import nees_over_truth  # noqa: E402
from fgslam.consistency_sample import in_band_se, sample_of_steps  # noqa: E402
from fgslam.runner import DEFAULT_ESTIMATORS, ESTIMATORS, run_estimator, truth_trajectory  # noqa: E402
from slamio.log.columns import read_columns  # noqa: E402

BASE_MODES = ("none", "all")


def shares(run, truth, has_pose) -> dict:
    """``{"nees": (share, count, se), "nis": (share, count, se)}`` of one run (None where not
    taken), the standard errors as metrics.json's."""
    out = {"nees": (None, 0, None), "nis": (None, 0, None)}
    if run.online_covariances is not None and has_pose.any():
        values, dofs = nees_over_truth(run.online, run.online_covariances, truth, has_pose)
        _, inside, count = chi2_summary(values, dofs)
        out["nees"] = (inside, count, in_band_se(inside, count))
    if run.nis is not None:
        _, inside, count = nis_summary(run.nis, run.nis_dofs)
        out["nis"] = (inside, count or 0, in_band_se_by_step(run.nis, run.nis_dofs, run.nis_steps) if count else None)
    return out


def measure(path: str, names, repeats: int, sizes=("default",), base_modes=BASE_MODES) -> tuple[dict, dict]:
    """``(cpu, figures)``: (estimator, mode) → minimum (steps CPU s, consistency CPU s, of which the
    landmark covariances after the run) over the repeats, and (estimator, mode) → :func:`shares` of the last repeat; a mode is ``none``,
    ``all``, ``default`` (``fgslam run``'s sample) or a sample size (``base_modes``: which of
    ``none`` and ``all`` to run besides ``sizes``)."""
    log = read_columns(path)
    steps = log.steps()
    truth, has_pose = truth_trajectory(steps)
    cpu: dict = {}
    figures: dict = {}
    for _ in range(repeats):
        for name in names:
            for mode in (*base_modes, *sizes):
                size = None if mode in (*BASE_MODES, "default") else int(mode)
                sample = sample_of_steps(steps, mode if mode in BASE_MODES else "sampled", size=size)
                run, _ = run_estimator(ESTIMATORS[name](log.header), steps, covariances=mode != "none", sample=sample)
                old = cpu.get((name, mode), (np.inf, np.inf, np.inf))
                cpu[(name, mode)] = (min(old[0], run.cpu_time_s), min(old[1], run.consistency_cpu_s or 0.0),
                                     min(old[2], run.map_covariance_cpu_s or 0.0))
                figures[(name, mode)] = shares(run, truth, has_pose)
    return cpu, figures


def _pct(value) -> str:
    return "-" if value is None else f"{100 * value:.1f}"


def print_costs(label: str, names, cpu: dict, sizes) -> None:
    modes = (*BASE_MODES, *sizes)
    for name in names:
        own = {mode: cpu[(name, mode)][0] for mode in modes}
        print_table_row(label, name, " / ".join(f"{own[m]:.3f}" for m in modes),
                        *(f"{cpu[(name, m)][1]:.3f} ({100 * cpu[(name, m)][1] / own['none']:.1f} %)" for m in modes[1:]))
    total_own = sum(cpu[(n, "none")][0] for n in names)
    total = {m: sum(cpu[(n, m)][1] for n in names) for m in modes[1:]}
    print_table_row(label, "all estimators", f"{total_own:.3f}",
                    *(f"{total[m]:.3f} ({100 * total[m] / total_own:.1f} %)" for m in modes[1:]))
    maps = {m: sum(cpu[(n, m)][2] for n in names) for m in modes[1:]}
    print_table_row(label, "of which the map's covariances", "",
                    *(f"{maps[m]:.3f} ({100 * maps[m] / total_own:.1f} %)" for m in modes[1:]))


def print_honesty(label: str, names, figures: dict, size: int) -> None:
    for name in names:
        for what in ("nees", "nis"):
            (every, n_every, _), (sampled, n_sampled, se) = figures[(name, "all")][what], figures[(name, size)][what]
            if every is None or sampled is None:
                continue
            z = (sampled - every) / se if se else float("nan")
            print_table_row(label, name, what.upper(), f"{_pct(every)} ({n_every})", f"{_pct(sampled)} ({n_sampled})",
                            f"{100 * se:.2f}" if se else "-", f"{z:+.2f}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="+", help="planar run logs (fgslam import ...)")
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--estimators", default=",".join(DEFAULT_ESTIMATORS))
    ap.add_argument("--sizes", default="default", help="sample sizes (steps drawn for NEES and for NIS), "
                    "comma-separated; default: fgslam run's (fgslam.consistency_sample.sample_size)")
    args = ap.parse_args(argv)
    names = args.estimators.split(",")
    sizes = tuple(args.sizes.split(","))
    results = {}
    for path in args.logs:
        results[Path(path).name] = measure(path, names, args.repeats, sizes)
        print(f"measured {path}", flush=True)
    print("CPU s of the estimators' own steps (modes: none / every step / samples of "
          f"{' / '.join(map(str, sizes))} steps) and of the consistency work (share of the own steps' time)")
    print_table_head("log", "estimator", "own steps by mode", "NEES+NIS every step",
                     *(f"NEES+NIS {k} steps" for k in sizes))
    for label, (cpu, _) in results.items():
        print_costs(label, names, cpu, sizes)
    for size in sizes:
        print(f"\nIn-band shares: every step against a sample of {size} steps (values in brackets), "
              "SE of the sample, difference / SE")
        print_table_head("log", "estimator", "figure", "every step % (n)", "sampled % (n)", "SE pts", "z")
        for label, (_, figures) in results.items():
            print_honesty(label, names, figures, size)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""``fgslam bench``: Monte Carlo over seeded simulations, average NEES against its band."""

from __future__ import annotations

import argparse
import contextlib
import json
from pathlib import Path

from fgslam.atomic import write_text_whole
from fgslam.cli.common import add_overwrite_option, add_verb, command_line, holds_outputs
from fgslam.cli.progress import Progress
from fgslam.cli.results import ResultsFolder
from fgslam.cli.verbs import help_of

OWN_NAMES = ("montecarlo.json", "nees.png", "ate.png")


def add_parser(verbs) -> argparse.ArgumentParser:
    from fgslam.cli.sim import SCENARIOS, STEREO_LOOP  # names only: the simulators load when used

    scenarios = (*SCENARIOS, STEREO_LOOP)
    bench = add_verb(
        verbs, "bench",
        help=help_of("bench"),
        description=(
            "Simulate SCENARIO with seeds SEED..SEED+RUNS-1, run the estimators on each (in a process\n"
            "pool, or on a Dask cluster), and report for each estimator the share of steps at which\n"
            "the NEES averaged over the runs lies inside its 95 % chi-square band (N = 50: [2.36, 3.72]),\n"
            "the ATE over the runs and the time (BLAS pinned to one thread in each worker).\n"
            "Simulations have ground truth at every pose.\n\n"
            f"{STEREO_LOOP}: seed 003's simulated car (stereo camera + IMU) with the 3-D estimators\n"
            "(default ekf-vio,ekf-vio-fej,isam2-3d); the NEES is on SE(3), 6 DoF (N = 10: [4.05, 8.33]),\n"
            "the ATE in 3-D."
        ),
    )
    bench.add_argument("scenario", choices=scenarios, metavar="SCENARIO", help=", ".join(scenarios))
    bench.add_argument("--runs", type=int, default=50, help="number of runs (default 50)")
    bench.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    bench.add_argument("--seed", type=int, default=0, help="first seed (default 0)")
    bench.add_argument("--estimators", default=None,
                       help=f"comma-separated (default ekf,isam2; on {STEREO_LOOP} ekf-vio,ekf-vio-fej,isam2-3d)")
    bench.add_argument("--landmarks", type=int, default=None, help="landmarks of the grid scenario (default 200)")
    bench.add_argument("--laps", type=int, default=None, help="laps (default: the scenario's; not for stereo-loop)")
    bench.add_argument("--out", default=None, metavar="DIR",
                       help="write montecarlo.json, nees.png, ate.png here (a new or empty folder, or an "
                            "earlier bench's: its files are replaced; one fgslam at a time writes a folder)")
    add_overwrite_option(bench, "fgslam's files in a --out folder that holds other files too")
    bench.add_argument("--dask", default=None, metavar="ADDRESS",
                       help="run on the Dask cluster at ADDRESS (needs the optional dask extra)")
    bench.set_defaults(func=cmd_bench)
    return bench


def _check_counts(args: argparse.Namespace) -> None:
    """The whole-number options, before a simulation or a worker starts: one line naming the
    option (a process pool of 0 workers, or a run of 0 laps, would fail only in the workers)."""
    from slamio.errors import FgslamError
    from slamio.sim import MAX_GRID_LANDMARKS

    for option, value, lowest, highest, what in (
        ("--runs", args.runs, 1, None, "how many seeded simulations"),
        ("--jobs", args.jobs, 1, None, "worker processes, e.g. 2 or the number of cores"),
        ("--seed", args.seed, 0, None, "the first seed"),
        ("--landmarks", args.landmarks, 1, MAX_GRID_LANDMARKS, "landmarks of the grid scenario"),
        ("--laps", args.laps, 1, None, "leave it out for the scenario's own number of laps"),
    ):
        if value is None:  # left out: the default
            continue
        if value < lowest or (highest is not None and value > highest):
            rule = f"from {lowest} to {highest}" if highest is not None else f">= {lowest}"
            raise FgslamError(f"{option} must be {rule} ({what}); got {value}")


@holds_outputs(out="--out")
def cmd_bench(args: argparse.Namespace) -> int:
    import numpy as np

    from fgslam.montecarlo import dask_executor, monte_carlo

    from fgslam.registry import BENCH_DEFAULTS, names_for
    from slamio.errors import FgslamError
    from slamio.sim3d import STEREO_LOOP

    _check_counts(args)
    dimension = 3 if args.scenario == STEREO_LOOP else 2
    if dimension == 3:
        planar_only = [flag for flag, value in (("--landmarks", args.landmarks), ("--laps", args.laps))
                       if value is not None]
        if planar_only:
            raise FgslamError(f"{', '.join(planar_only)}: not available for {STEREO_LOOP} (its drive is one fixed loop)")
    known, default = names_for(dimension), BENCH_DEFAULTS[dimension]
    text = ",".join(default) if args.estimators is None else args.estimators
    estimators = tuple(n.strip() for n in text.split(",") if n.strip())
    unknown = [e for e in estimators if e not in known]
    if unknown or not estimators:
        raise FgslamError(f"unknown estimator(s) {', '.join(unknown) or '(none given)'} for {args.scenario}; "
                          f"choose from {', '.join(known)} (comma-separated)")
    results = None
    if args.out is not None:  # before the runs: nothing computed for nothing
        results = ResultsFolder(args.out, overwrite=args.overwrite, verb="bench", own_names=OWN_NAMES).check()
    with dask_executor(args.dask) if args.dask else contextlib.nullcontext() as executor, \
            Progress(unit="runs") as progress:
        progress(0, args.runs, "monte carlo")
        result = monte_carlo(
            args.scenario, args.runs, estimators=estimators, first_seed=args.seed, jobs=args.jobs,
            landmarks=200 if args.landmarks is None else args.landmarks, laps=args.laps, executor=executor,
            progress=progress,
        )
    low, high = result.band
    steps = len(next(iter(result.average_nees.values())))
    scored = steps if result.scored_steps is None else int(np.count_nonzero(result.scored_steps))
    judged = "" if scored == steps else f" ({scored} with truth in every run are judged)"
    print(f"Monte Carlo: {args.scenario}, {args.runs} runs (seeds {args.seed}-{args.seed + args.runs - 1}), "
          f"{steps} steps{judged}; 95 % band of the average NEES over {args.runs} runs: [{low:.3f}, {high:.3f}]")
    header = f"{'estimator':<14}{'inside band':>12}{'above band':>12}{'mean NEES':>11}" \
             f"{'ATE final m (median, max)':>28}{'time s (mean)':>15}"
    print(header)
    summary = {"scenario": args.scenario, "runs": args.runs, "first_seed": args.seed, "steps": steps,
               "nees_dof": result.dof, "band": [low, high], "estimators": {}}
    for name in estimators:
        finals = np.array([r.ate_final_m[name] for r in result.runs])
        times = np.array([r.time_s[name] for r in result.runs])
        print(f"{name:<14}{100 * result.share_inside(name):11.1f}%{100 * result.share_above(name):11.1f}%"
              f"{result.mean_nees(name):11.2f}"
              f"{np.median(finals):14.4f}, {np.max(finals):.4f}{'':>4}{np.mean(times):13.3f}")
        summary["estimators"][name] = {
            "share_inside_band": result.share_inside(name),
            "share_above_band": result.share_above(name),
            "average_nees": [float(v) if np.isfinite(v) else None for v in result.average_nees[name]],
            "ate_final_m": [float(v) for v in finals],
            "ate_online_m": [float(r.ate_online_m[name]) for r in result.runs],
            "time_s": [float(v) for v in times],
        }
    if results is not None:
        from fgslam.report import write_monte_carlo_figures
        from fgslam.runner import TIMING

        summary["timing"] = TIMING["what"]
        summary["blas_threads"] = TIMING["blas_threads"]
        out = Path(args.out)
        results.clear()
        with results.filling(command=command_line(args, "bench")):
            write_text_whole(out / "montecarlo.json", json.dumps(summary, indent=1) + "\n")
            written = ["montecarlo.json"] + write_monte_carlo_figures(out, result)
            results.finish(command=command_line(args, "bench"))
        print(f"\nwrote {', '.join(written + ['manifest.json'])} to {out}/")
    return 0

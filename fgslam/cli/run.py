"""``fgslam run``: run the estimators on a log and write the comparison to a results folder."""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

from fgslam.atomic import write_text_whole
from fgslam.cli.common import add_overwrite_option, add_verb, command_line, holds_outputs, read_counted, tally_of
from fgslam.cli.estimators import ESTIMATOR_HELP, ESTIMATOR_HELP_3D
from fgslam.cli.progress import Progress
from fgslam.cli.results import ResultsFolder
from fgslam.cli.verbs import help_of
from fgslam.failure import FAILED_EXIT_STATUS
from slamio.errors import FgslamError

#: File names ``fgslam run`` writes besides <estimator>[_online].tum and the report's PNGs:
#: what --overwrite (or an output from before manifests) replaces in a folder without a manifest.
OWN_NAMES = ("metrics.json", "report.html", "graph.g2o", "reference.tum")


def own_names() -> list[str]:
    """Every file name ``fgslam run`` can write (for a folder without a manifest)."""
    from fgslam import report
    from fgslam.registry import REGISTRY

    names = list(OWN_NAMES)
    for name in [*REGISTRY, "batch"]:
        names += [f"{name}.tum", f"{name}_online.tum"]
    names += [value for key, value in vars(report).items()
              if key.endswith(("_PNG", "_HTML")) and isinstance(value, str)]
    return names


def add_parser(verbs) -> argparse.ArgumentParser:
    run = add_verb(
        verbs, "run",
        help=help_of("run"),
        epilog="estimators:\n" + "\n".join(f"  {name:<15} {text}" for name, text in ESTIMATOR_HELP.items())
        + "\n\nestimators of a 3-D log (seed 003: stereo camera + IMU):\n"
        + "\n".join(f"  {name:<16} {text}" for name, text in ESTIMATOR_HELP_3D.items())
        + "\n\ntiming: the wall time of each estimator.step (and finish() in the total), with\n"
          "BLAS/OpenMP pinned to one thread (threadpoolctl), so the figures compare the\n"
          "algorithms, not how many cores a BLAS grabs; NEES/NIS work is outside the timed region.\n\n"
          "exit status: 0 when every estimator ran through; "
          f"{FAILED_EXIT_STATUS} when an estimator failed mid-run\n"
          "(an exception such as gtsam's IndeterminateSystemException, or a pose or covariance that\n"
          "is not a number): its row says 'failed at step N: reason', metrics.json has\n"
          "{\"failed\": {\"step\": N, \"time_s\": t, \"reason\": ...}} for it, and the other estimators'\n"
          "results are written; 1 for a mistake in the command, or when the failure leaves no\n"
          "reference (the batch solve, or every iSAM2 it starts from, failed on a log without\n"
          "pose truth); 2 when the log cannot be used.",
        description=(
            "Run every estimator on the same log and compare them. The reference is the log's\n"
            "ground truth wherever it has some: with gaps in the truth (e.g. Vicon drop-outs)\n"
            "only the poses with truth are scored, and the first line of the table says how\n"
            "many. Without any pose truth it is the batch Levenberg-Marquardt solution started\n"
            "from iSAM2's result (the 'smoothed ground truth'), and the map error is against the\n"
            "log's surveyed landmarks when it has them. Writes\n"
            "metrics.json, report.html (self-contained), PNG figures, and each estimator's\n"
            "trajectory in TUM format (<name>.tum final, <name>_online.tum online) to --out,\n"
            "and prints a table of the figures.\n\n"
            "--out is a new or empty folder, or the folder of an earlier fgslam run on the same\n"
            "log: its files (listed in its manifest.json) are replaced, so no stale file of the\n"
            "earlier run remains. A folder with other files, or with the results of another log\n"
            "or of fgslam bench, is refused unless --overwrite; folders and symbolic links in it\n"
            "are never removed. One fgslam at a time writes a --out: a second is refused.\n"
            "Every file is written whole: if the disk fills up, the error names the file, the\n"
            "files written whole are kept (manifest.json says \"complete\": false), and the same\n"
            "command run again replaces them."
        ),
    )
    run.add_argument("log", metavar="LOG", help="run log (.jsonl)")
    run.add_argument("--out", required=True, metavar="DIR", help="folder for the results (created)")
    add_overwrite_option(run, "fgslam's files in a --out folder that holds other files too (they are left alone)")
    run.add_argument(
        "--estimators",
        default=None,
        metavar="LIST",
        help="comma-separated estimators to run (default ekf,isam2,dead_reckoning; on a 3-D log "
        "ekf-s003,ekf-vio,ekf-vio-fej,isam2-3d; all names below); the batch solve always runs from isam2's "
        "(isam2-3d's) result",
    )
    run.add_argument("--noise", default=None, metavar="FILE",
                     help="a noise model from `fgslam calibrate LOG... --out FILE`, applied to this log's "
                          "odometry and readings before the run (slamio.noise.apply; an importer that has the "
                          "raw data applies it exactly: prefer `fgslam import ... --noise FILE`); "
                          "`--noise self`: learn it from this log first, without truth "
                          "(`fgslam calibrate LOG --without-truth`)")
    run.add_argument("--calibration", default=None, metavar="CAL.json",
                     help="seed 001's trial calibration from `fgslam calibrate TRIALS.csv --out CAL.json`: "
                          "ekf-s001 takes its R and Q from it (as `fgslam record --calibration` does); with "
                          "--noise self the fit holds the odometry's scales at the trials'")
    run.add_argument("--odometry-window", type=float, default=None, metavar="S",
                     help="with --noise self: learn the odometry's variance rates from its steps chained over "
                          "S-second stretches (default: step by step), as `fgslam calibrate --without-truth "
                          "--odometry-window S` does")
    run.add_argument("--no-report", action="store_true", help="skip report.html and the PNG figures")
    run.add_argument("--consistency", choices=("sampled", "all", "none"), default="sampled",
                     help="where NEES, NIS and the covariance ellipses are taken on a planar log: at a seeded "
                          "sample of steps, the same for every estimator (default; the table gives each share's "
                          "standard error), at every step (`all`: their work, untimed between the steps, costs "
                          "iSAM2 more than its own steps and slows them by 30-50%% on real logs), or not at all; "
                          "a 3-D log takes them at every step unless `none`")
    run.add_argument("--no-consistency", action="store_true",
                     help="skip NEES, NIS and covariance ellipses (= --consistency none; use this for timings)")
    run.set_defaults(func=cmd_run)
    return run


def with_trial_calibration(log, path):
    """``log`` with the trial calibration at ``path`` in its header (``noise.calibration``)."""
    import dataclasses

    from slamio.noise.trials import load_calibration

    noise = {**log.header.noise, "calibration": load_calibration(path).to_dict()}
    return dataclasses.replace(log, header=dataclasses.replace(log.header, noise=noise))


@holds_outputs(out="--out")
def cmd_run(args: argparse.Namespace) -> int:
    """One path for every log: read it once, pick its estimators from the registry by the
    log's dimension, run them, compute the metrics (one schema), write, print the table."""
    # The results folder first (before the estimators are even loaded): an unusable --out is
    # one line at once, never a FileExistsError after the whole run.
    results = ResultsFolder(args.out, overwrite=args.overwrite, verb="run", own_names=own_names,
                            source=str(Path(args.log).resolve())).check()

    from fgslam.failure import with_failures
    from fgslam.provenance import provenance
    from fgslam.registry import parse_names
    from fgslam.runner import TIMING, require_motion
    from fgslam.verdict import verdict_lines

    # a planar log into columns unless --noise needs its records: the run then holds numbers, not records
    log, tally = read_counted(args.log, columns=args.noise is None)
    require_motion(log, "estimate or score")
    dimension = 3 if log.header.is_3d else 2
    if getattr(args, "odometry_window", None) is not None and (args.noise != "self" or dimension == 3):
        raise FgslamError("--odometry-window sets the stretch the odometry's variance is learned over with "
                          "--noise self on a planar log" + (f"; {args.log} is a 3-D log" if dimension == 3 else ""))
    if dimension == 3:  # seed 003's stereo + IMU logs: their records carry their noise
        for flag, value in (("--noise", args.noise), ("--calibration", args.calibration)):
            if value is not None and not (flag == "--noise" and value == "self"):
                raise FgslamError(f"{flag} applies to planar logs; {args.log} is a 3-D log (its records carry "
                                  "their noise; --noise self learns it from the log)")
        if args.noise == "self":
            log = _self_fitted_3d(log)
    # 2-D without iSAM2 has no batch solve: fine where the log's truth is the reference (compare_log says)
    names = parse_names(args.estimators, dimension, need_isam2=dimension == 3)
    if dimension == 2:
        log = _with_side_inputs(args, log)
    if tally is None:  # read whole: counted from its records (after --noise, as the estimators see it)
        tally = tally_of(log)
    print(f"{args.log}: {'3-D log, ' if dimension == 3 else ''}{tally.text()}")
    compare, compute_metrics, format_table, write_results = _pipeline(dimension)
    with Progress() as progress:
        result = compare(log, names, progress=progress, consistency=_consistency_mode(args, dimension))
        progress(0, 1, "metrics")  # errors against the reference, NEES/NIS over every step: seconds on long runs
        metrics = with_failures(compute_metrics(result, log_path=str(args.log)), result.failures, [*names, "batch"])
        progress(1, 1, "metrics")
    metrics["timing"] = TIMING["what"]  # strings: not mistaken for an estimator
    metrics["blas_threads"] = TIMING["blas_threads"]
    if log.truncated:
        metrics["log_truncated"] = log.truncated
    if getattr(log, "rejected", None):
        metrics["log_rejected"] = log.rejection_summary()
    events = tally.event_counts()
    if events:  # what the robot met (bumps, cliffs, wheel drops); the estimators ignore them
        metrics["events"] = events
    if args.noise is not None:
        metrics["noise_model"] = str(args.noise)
    if args.calibration is not None:
        metrics["trial_calibration"] = str(args.calibration)
    short = result.smoother_short_of_optimum()
    if short is not None:
        metrics["smoother_short_of_optimum"] = short
    verdict = getattr(result, "verdict", None) or {}
    if verdict:
        metrics["noise_verdict"] = {group: v.as_dict() for group, v in verdict.items()}
        metrics["noise_source"] = noise_source(log.header)
    ran = [*(r.name for r in result.runs), *(f.name for f in result.failures)]
    metrics["provenance"] = provenance(args.log, ran, command=command_line(args, "run"))

    replaced = results.clear()
    with results.filling(**run_provenance(args)), Progress() as progress:
        progress(0, 1, "writing the results")  # the figures and report.html take seconds on long runs
        written = write_results(args, metrics, result)
        results.finish(**run_provenance(args))
        progress(1, 1, "writing the results")
    mode = _consistency_mode(args, 2) if dimension == 2 and any(name.startswith("isam2") for name in names) else "none"
    return finish_run(args, results, log, written, replaced, format_table(metrics), notes=[short] if short else [],
                      timing_note={"all": TIMING["consistency_note"], "sampled": TIMING["sampled_note"]}.get(mode),
                      verdict=verdict_lines(verdict, metrics.get("noise_source")) if verdict else [],
                      failures=result.failures)


def _consistency_mode(args: argparse.Namespace, dimension: int) -> str | bool:
    """``compare_log``'s ``consistency`` for ``--consistency`` / ``--no-consistency`` (a bool
    for a 3-D log: its runner takes NEES at every step or not at all)."""
    mode = "none" if args.no_consistency else args.consistency
    return mode != "none" if dimension == 3 else mode


def noise_source(header) -> str:
    """Where the log's noise came from, in a few words (its header's ``noise`` and ``source``)."""
    noise = header.noise if isinstance(header.noise, dict) else {}
    if "learned_without_truth" in noise:
        return "learned from this log without truth (--noise self)"
    if header.source.get("generator") in ("slamio.sim", "slamio.sim3d") and "fitted_on" not in noise:
        return "the simulator's own (drawn exactly as stated)"
    if "fitted_on" in noise:
        fitted = noise.get("fitted_on") or []
        return "a fitted noise model" + (f" (fitted on {', '.join(map(str, fitted))})" if fitted else "")
    texts = [str(part.get("model", "")) for part in noise.values() if isinstance(part, dict)]
    sources = [str(part.get("source", "")) for part in noise.values() if isinstance(part, dict)]
    if any("not fitted" in t for t in texts) or any("uncalibrated" in t for t in sources):
        return "round numbers, not fitted to this robot (the importer's or recorder's defaults)"
    text = "; ".join(t for t in texts if t) or "not stated in the log's header"
    return text if len(text) <= 160 else text[:157] + "..."


def _pipeline(dimension: int):
    """``(compare, compute_metrics, format_table, write_results)`` for a log of ``dimension``:
    the one place ``fgslam run`` tells a planar log from a 3-D one."""
    if dimension == 3:
        from fgslam.runner3d import compute_metrics_3d, format_table_3d, run_log3d

        return run_log3d, compute_metrics_3d, format_table_3d, _write_results_3d
    from fgslam.compare import compute_metrics, format_table
    from fgslam.runner import compare_log

    def metrics_2d(result, *, log_path: str) -> dict:
        return compute_metrics(result.runs, result.reference, log_path=log_path)

    return compare_log, metrics_2d, format_table, _write_results


def _with_side_inputs(args: argparse.Namespace, log):
    """The planar ``log`` with --noise's model and --calibration's R and Q applied (if given)."""
    if args.noise is not None:
        from fgslam.cli.calibrate import odometry_window
        from slamio.noise.apply import apply_noise_model
        from slamio.noise.model import load_noise_model

        if log.header.source.get("generator") == "slamio.sim":
            raise FgslamError(f"{args.log} was simulated (fgslam sim): its noise is the simulator's own and its "
                              "covariances are exact, so a fitted noise model does not apply; --noise is for a log "
                              "recorded or imported without one")
        model = _self_fitted_model(log, args.calibration, odometry_window(args, None)) if args.noise == "self" \
            else load_noise_model(args.noise)
        log, dropped = apply_noise_model(log, model)
        if args.noise == "self":  # the verdict then knows the noise is this log's own
            noise = {**log.header.noise, "learned_without_truth": True}
            log = dataclasses.replace(log, header=dataclasses.replace(log.header, noise=noise))
        what = "the noise model learned from this log (without truth)" if args.noise == "self" else \
            f"the noise model {args.noise}"
        print(f"applied {what}" + (f" ({dropped} readings could not be corrected and were dropped)" if dropped else ""))
    if args.calibration is not None:
        log = with_trial_calibration(log, args.calibration)
        print(f"seed 001's R and Q from the trial calibration {args.calibration}")
    return log


def _self_fitted_model(log, calibration: str | None = None, window_s: float | None = None):
    """``--noise self``: the noise model :func:`fgslam.self_calibration.fit_without_truth`
    learns from ``log`` alone (the odometry's scales held at the trial ``calibration``'s,
    when given; its variances over ``window_s``-second stretches, when given), its summary printed."""
    from fgslam.cli.calibrate import noise_model_summary, self_fit_notes, trial_scales
    from fgslam.cli.progress import Progress
    from fgslam.self_calibration import fit_without_truth

    pinned = None if calibration is None else trial_scales(calibration)
    with Progress(unit="") as progress:
        fit = fit_without_truth([log], progress=progress, pinned=pinned, odometry_window_s=window_s)
    print(noise_model_summary(fit.model))
    print(self_fit_notes(fit))
    return fit.model


def _self_fitted_3d(log):
    """``--noise self`` on a 3-D log: the stereo and IMU σ learned from it
    (:func:`fgslam.self_calibration3d.fit_without_truth_3d`) written into its records."""
    from fgslam.cli.progress import Progress
    from fgslam.runner3d import prepare_log3d
    from fgslam.self_calibration3d import fit_without_truth_3d, with_noise

    with Progress(unit="") as progress:
        fit = fit_without_truth_3d(prepare_log3d(log), progress=progress)
    n = fit.noise
    print(f"learned without truth in {fit.iterations} iterations"
          + ("" if fit.converged else " (NOT converged: the last iteration's values)")
          + f": stereo {'' if n.pixel_covariance is None else 'RMS '}sigma {n.sigma_px:.3f} px"
          + ("" if n.pixel_covariance is None else " (the log's 4x4 pixel covariance, scaled)")
          + f", IMU speed sigma {n.sigma_v_mps:.4f} m/s, "
          f"turn-rate sigma {n.sigma_w_radps:.5f} rad/s (the log said {_stated_3d(log)}); "
          f"{100 * fit.outlier_rate:.1f} % of the stereo observations beyond the fit's gate")
    print("applied the noise learned from this log (without truth)")
    return with_noise(log, n)


def _stated_3d(log) -> str:
    import numpy as np

    from fgslam.runner3d import noise_of

    n = noise_of(log)
    cov = n.velocity_cov()
    pixels = f"{n.sigma_px:g} px" if n.pixel_covariance is None else f"a 4×4 pixel covariance (RMS {n.sigma_px:.3g} px)"
    return (f"{pixels}, {float(np.sqrt(np.mean(np.diag(cov)[:3]))):g} m/s, "
            f"{float(np.sqrt(np.mean(np.diag(cov)[3:]))):g} rad/s")


def _write_metrics_and_tum(out: Path, metrics: dict, result, has_pose, write, online: list) -> None:
    """metrics.json; with ``write`` (a TUM writer) reference.tum, NAME.tum of each run's final
    trajectory and NAME_online.tum of each run in ``online``."""
    write_text_whole(out / "metrics.json", json.dumps(metrics, indent=2) + "\n")
    # TUM files are stamped: leave the poses without truth (not in has_pose) out
    write(out / "reference.tum", result.stamps_s[has_pose], result.reference.trajectory[has_pose])
    for run in result.runs:
        write(out / f"{run.name}.tum", result.stamps_s, run.final)
    for run in online:
        write(out / f"{run.name}_online.tum", result.stamps_s, run.online)


def _write_results(args: argparse.Namespace, metrics: dict, result) -> list[str]:
    """metrics.json, the TUM files, graph.g2o and the report of a planar run into --out; each
    file whole or not at all. Returns what to say was written."""
    from fgslam.compare import write_tum
    from fgslam.export import write_g2o

    out = Path(args.out)
    online = [run for run in result.runs if run.online is not None]
    _write_metrics_and_tum(out, metrics, result, result.reference.has_pose, write_tum, online)
    written = ["metrics.json", "*.tum"]
    smoother = result.smoother  # its graph, vertices at iSAM2's final estimate (none: no iSAM2 ran)
    if smoother is not None:
        write_g2o(out / "graph.g2o", smoother.graph(), smoother.estimate(), smoother.num_poses)
        written.append("graph.g2o")
    if not args.no_report:
        from fgslam.report import write_report

        html = write_report(
            out, metrics, result.runs, result.reference, result.stamps_s, title=f"fgslam run {Path(args.log).name}"
        )
        written.insert(1, html.name)
    return written


def run_provenance(args: argparse.Namespace) -> dict:
    """What the manifest of ``fgslam run`` records about the command."""
    return {"command": command_line(args, "run"), "log": str(args.log)}


def finish_run(args: argparse.Namespace, results, log, written: list[str], replaced, table: str,
               notes: list[str] = (), timing_note: str | None = None, verdict: list[str] = (),
               failures=()) -> int:
    """Print the table and say what was written (the folder is sealed: its manifest is written).
    The exit status: 0, or :data:`fgslam.failure.FAILED_EXIT_STATUS` when an estimator failed
    (``failures``, :class:`fgslam.failure.EstimatorFailure`; each also said on stderr)."""
    from fgslam.runner import TIMING

    written.append("manifest.json")
    print()
    print(table)
    print(f"time: {TIMING['what']}")
    if timing_note:
        print(f"      {timing_note}")
    if verdict:
        print()
        print("\n".join(verdict))
    stale = sorted(set(replaced) - set(results.finish_names) - {"manifest.json"})
    note = f" (replacing the earlier results; {len(stale)} of its files not written again were removed: " \
           f"{', '.join(stale[:4])}{', ...' if len(stale) > 4 else ''})" if stale else \
           (" (replacing the earlier results)" if replaced else "")
    print(f"\nwrote {', '.join(written)} to {Path(args.out)}/{note}")
    if log.truncated:
        print(f"note: {log.truncated}")
    for text in notes:
        print(f"note: {text}")
    for failure in failures:
        print(f"fgslam: {failure.sentence()}; the other estimators' results are written to {Path(args.out)}/ "
              f"(exit status {FAILED_EXIT_STATUS})", file=sys.stderr)
    return FAILED_EXIT_STATUS if failures else 0


def _write_results_3d(args: argparse.Namespace, metrics: dict, result) -> list[str]:
    """metrics.json, the TUM files and the report of a 3-D run into --out; each file whole or
    not at all. Returns what to say was written."""
    from fgslam.runner3d import reference_line_3d, table_rows_3d, write_tum3

    out = Path(args.out)
    online = [run for run in result.runs if run.online is not None and run.online is not run.final]
    _write_metrics_and_tum(out, metrics, result, result.reference.mask, write_tum3, online)
    written = ["metrics.json", "*.tum"]
    if not args.no_report:
        from fgslam.report import write_report_3d

        header, rows = table_rows_3d(metrics)
        html = write_report_3d(out, metrics, result.runs, result.reference, title=f"fgslam run {Path(args.log).name}",
                               table_header=header, table_rows=rows, reference_text=reference_line_3d(metrics))
        written.insert(1, html.name)
    return written

"""``fgslam run`` on a 3-D log (seed 003's stereo + IMU): the 3-D estimators, table, TUM files, report."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from fgslam.atomic import write_text_whole
from fgslam.cli.common import command_line, summary
from fgslam.cli.progress import Progress
from slamio.errors import FgslamError


def cmd_run3d(args: argparse.Namespace, results, log) -> int:
    """Run the 3-D estimators on ``log`` and write into the checked ``results`` folder."""
    from fgslam.cli.run import finish_run, run_provenance
    from fgslam.provenance import provenance
    from fgslam.runner import TIMING
    from fgslam.runner3d import (
        compute_metrics_3d,
        format_table_3d,
        parse_estimator_names_3d,
        run_log3d,
    )

    for flag, value in (("--noise", args.noise), ("--calibration", args.calibration)):
        if value is not None:
            raise FgslamError(f"{flag} applies to planar logs; {args.log} is a 3-D log (its records carry their noise)")
    names = parse_estimator_names_3d(args.estimators)
    print(f"{args.log}: 3-D log, {summary(log)}")
    with Progress() as progress:
        result = run_log3d(log, names, consistency=not args.no_consistency, progress=progress)
    metrics = compute_metrics_3d(result, log_path=str(args.log))
    metrics["timing"] = TIMING["what"]
    if log.truncated:
        metrics["log_truncated"] = log.truncated
    metrics["provenance"] = provenance(args.log, [r.name for r in result.runs], command=command_line(args, "run"))

    replaced = results.clear()
    with results.filling(**run_provenance(args)):
        written = _write_results_3d(args, metrics, result)
        results.finish(**run_provenance(args))
    return finish_run(args, results, log, written, replaced, format_table_3d(metrics))


def _write_results_3d(args: argparse.Namespace, metrics: dict, result) -> list[str]:
    """metrics.json, the TUM files and the report of a 3-D run into --out; each file whole or
    not at all. Returns what to say was written."""
    from fgslam.runner3d import reference_line_3d, table_rows_3d, write_tum3

    out = Path(args.out)
    write_text_whole(out / "metrics.json", json.dumps(metrics, indent=2) + "\n")
    has_pose = result.reference.mask  # TUM files are stamped: leave the poses without truth out
    write_tum3(out / "reference.tum", result.stamps_s[has_pose], result.reference.trajectory[has_pose])
    for run in result.runs:
        write_tum3(out / f"{run.name}.tum", result.stamps_s, run.final)
        if run.online is not None and run.online is not run.final:
            write_tum3(out / f"{run.name}_online.tum", result.stamps_s, run.online)
    written = ["metrics.json", "*.tum"]
    if not args.no_report:
        from fgslam.report import write_report_3d

        header, rows = table_rows_3d(metrics)
        html = write_report_3d(out, metrics, result.runs, result.reference, title=f"fgslam run {Path(args.log).name}",
                               table_header=header, table_rows=rows, reference_text=reference_line_3d(metrics))
        written.insert(1, html.name)
    return written

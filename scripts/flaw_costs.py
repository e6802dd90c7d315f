#!/usr/bin/env python3
"""What does each seed paper's flaw cost? Run every paper variant as written, with each
flaw switched off in turn and with all of them off, on the bundled logs, and print a
markdown table of final ATE and map RMSE against ground truth (docs/estimators.md quotes it).

    python -m scripts.flaw_costs                 # data/arena_octagon.jsonl, data/arena_square.jsonl
    python -m scripts.flaw_costs LOG [LOG ...]

Every setting is a keyword of the variant's class; the defaults are the paper as written.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ekf import EkfS000, EkfS001, EkfS004, EkfSlam
from fgslam.compare import compute_metrics
from fgslam.runner import run_estimator, truth_reference
from slamio.log import read_log
from scripts.common import ROOT

DEFAULT_LOGS = [ROOT / "data" / "arena_octagon.jsonl", ROOT / "data" / "arena_square.jsonl"]

S000_FIXED = {"rotation": "compass", "landmark_init": "offset-from-robot", "noise": "log",
              "pseudo_measurements": False, "gain_zeroing": False}
S001_FIXED = {"q_diagonal": "variance", "motion_model": "arc", "motion_noise": "log"}
S004_FIXED = {"rotate_input": True, "substate_update": False}

#: (label, estimator class, keywords). A row "without X" switches only flaw X off.
SETTINGS = [
    ("ekf (textbook EKF-SLAM)", EkfSlam, {}),
    ("ekf-s000 as written", EkfS000, {}),
    ("ekf-s000 without the anticlockwise input rotation", EkfS000, {"rotation": "compass"}),
    ("ekf-s000 without relative-position landmark init", EkfS000, {"landmark_init": "offset-from-robot"}),
    ("ekf-s000 with both geometry fixes", EkfS000, {"rotation": "compass", "landmark_init": "offset-from-robot"}),
    ("ekf-s000 geometry fixed, log noise instead of unit variances", EkfS000,
     {"rotation": "compass", "landmark_init": "offset-from-robot", "noise": "log"}),
    ("ekf-s000 geometry fixed, no pseudo-measurements of unseen landmarks", EkfS000,
     {"rotation": "compass", "landmark_init": "offset-from-robot", "pseudo_measurements": False}),
    ("ekf-s000 geometry fixed, no gain-row zeroing", EkfS000,
     {"rotation": "compass", "landmark_init": "offset-from-robot", "gain_zeroing": False}),
    ("ekf-s000 all switchable flaws off (heading still treated as known)", EkfS000, S000_FIXED),
    ("ekf-s001 as written", EkfS001, {}),
    ("ekf-s001 without sigma-for-variance in Q", EkfS001, {"q_diagonal": "variance"}),
    ("ekf-s001 without forward-then-rotate moves (arc)", EkfS001, {"motion_model": "arc"}),
    ("ekf-s001 without the constant motion covariance", EkfS001, {"motion_noise": "log"}),
    ("ekf-s001 all three off", EkfS001, S001_FIXED),
    ("ekf-s001 prediction only (what the paper ran)", EkfS001, {"correction": False}),
    ("ekf-s004 as written", EkfS004, {}),
    ("ekf-s004 without unrotated body velocity", EkfS004, {"rotate_input": True}),
    ("ekf-s004 without the sub-state update", EkfS004, {"substate_update": False}),
    ("ekf-s004 both off (heading still treated as known)", EkfS004, S004_FIXED),
]


def measure(log_path: Path) -> dict[str, dict]:
    log = read_log(log_path)
    reference = truth_reference(log)
    if reference is None:
        raise SystemExit(f"{log_path}: needs ground truth for every pose")
    steps = log.steps()
    out = {}
    for label, cls, keywords in SETTINGS:
        run, _ = run_estimator(cls(log.header, **keywords), steps, covariances=False)
        out[label] = compute_metrics([run], reference, log_path=str(log_path))[run.name]
    return out


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("logs", nargs="*", type=Path, metavar="LOG",
                        help="run logs with ground truth (default: data/arena_octagon.jsonl, data/arena_square.jsonl)")
    args = parser.parse_args(argv)
    missing = [str(p) for p in args.logs if not p.is_file()]
    if missing:
        parser.error(f"no such log: {missing[0]}")
    logs = args.logs or DEFAULT_LOGS
    results = {path.name: measure(path) for path in logs}
    names = list(results)
    print("| setting | " + " | ".join(f"ATE {n} m | map {n} m" for n in names) + " |")
    print("|---|" + "---|---|" * len(names))
    for label, _, _ in SETTINGS:
        cells = []
        for n in names:
            m = results[n][label]
            cells += [f"{m['ate_rmse_m']:.3f}", "-" if m["map_rmse_m"] is None else f"{m['map_rmse_m']:.3f}"]
        print(f"| {label} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

"""Cut the short MRCLAM excerpt the tests ship (tests/data/mrclam_excerpt) from a full folder.

Keeps the first ``--seconds`` (default 150 s) of robots ``--robots`` (default 1,2,3) from the
run's common start, every line of ``Barcodes.dat`` and ``Landmark_Groundtruth.dat``, all
odometry and measurement lines in that span, and every ``--truth-every``-th ground-truth
line (default 5: Vicon's ~100 Hz to ~20 Hz, which the importer interpolates). The files keep
the published layout (four ``#`` header lines, the same columns and number formats).

Usage::

    .venv/bin/python -m scripts.make_mrclam_excerpt ../shared/data/mrclam/MRCLAM_Dataset6 tests/data/mrclam_excerpt
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys


def _split(path: str) -> tuple[list[str], list[str]]:
    with open(path) as f:
        lines = f.readlines()
    header = [line for line in lines if line.startswith("#")]
    data = [line for line in lines if line.strip() and not line.startswith("#")]
    return header, data


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("source", help="an MRCLAM_DatasetK folder")
    parser.add_argument("out", help="folder to write (must not exist)")
    parser.add_argument("--robots", default="1,2,3")
    parser.add_argument("--seconds", type=float, default=150.0)
    parser.add_argument("--truth-every", type=int, default=5)
    args = parser.parse_args(argv)
    if os.path.exists(args.out):
        print(f"{args.out} exists; choose another folder or delete it", file=sys.stderr)
        return 1
    robots = [int(r) for r in args.robots.split(",")]
    starts = []
    for k in robots:
        for kind in ("Odometry", "Groundtruth"):
            _, data = _split(os.path.join(args.source, f"Robot{k}_{kind}.dat"))
            starts.append(float(data[0].split()[0]))
    start = max(starts)
    end = start + args.seconds
    os.makedirs(args.out)
    for name in ("Barcodes.dat", "Landmark_Groundtruth.dat"):
        shutil.copy(os.path.join(args.source, name), os.path.join(args.out, name))
    for k in robots:
        for kind in ("Odometry", "Measurement", "Groundtruth"):
            header, data = _split(os.path.join(args.source, f"Robot{k}_{kind}.dat"))
            # odometry and truth from the first line at or before the start, so the run can begin there
            keep = [line for line in data if float(line.split()[0]) <= end]
            if kind != "Measurement":
                first = max(i for i, line in enumerate(keep) if float(line.split()[0]) <= start - 5.0) if any(
                    float(line.split()[0]) <= start - 5.0 for line in keep) else 0
                keep = keep[first:]
            else:
                keep = [line for line in keep if float(line.split()[0]) >= start - 5.0]
            if kind == "Groundtruth":
                keep = keep[:: args.truth_every]
            with open(os.path.join(args.out, f"Robot{k}_{kind}.dat"), "w") as f:
                f.writelines(header + keep)
    print(f"wrote {args.out}: robots {args.robots}, {args.seconds:.0f} s from {start:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

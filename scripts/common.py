"""What several benchmarks of :mod:`scripts` share: BLAS pinning, paths, argument parsers.

Imports nothing heavy (no numpy): :func:`one_blas_thread` must run before numpy loads, so a
script calls it first::

    from scripts.common import one_blas_thread

    one_blas_thread()

    import numpy as np  # noqa: E402
"""

from __future__ import annotations

import ast
import os
from pathlib import Path

#: The repository's root (the folder holding ``scripts/``, ``data/`` and ``tests/``).
ROOT = Path(__file__).resolve().parents[1]
#: The logs bundled with the repository.
DATA = ROOT / "data"
#: The test data (the NASA AprilTag photos, the real RGB-D frames, the MRCLAM excerpt).
TEST_DATA = ROOT / "tests" / "data"
#: The NASA AprilTag photos and their listings.
APRILTAG_PHOTOS = TEST_DATA / "apriltag-photos"
#: The large data sets kept next to the repository (MRCLAM, the real RGB-D frames, seed 003's
#: drives), not in it: ``../shared/data`` from the root.
SHARED_DATA = ROOT.parent / "shared" / "data"


def one_blas_thread(force: bool = True) -> None:
    """BLAS (OpenBLAS, OpenMP) on one thread; call before numpy is imported.

    On a shared machine a multithreaded BLAS made single iSAM2 updates about 20× slower under
    load, and timings comparable across runs need one thread. ``force`` overrides an
    ``OPENBLAS_NUM_THREADS`` the caller set (the benchmarks); without it a set value wins
    (the measurements, whose numbers do not depend on threads)."""
    if force:
        os.environ["OPENBLAS_NUM_THREADS"] = "1"
    else:
        os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    os.environ.setdefault("OMP_NUM_THREADS", "1")


def parse_seeds(text: str) -> list[int]:
    """``"1-10"`` → 1, 2, …, 10 (both ends included); ``"1,4,7"`` → those seeds."""
    if "-" in text:
        first, last = (int(v) for v in text.split("-"))
        return list(range(first, last + 1))
    return [int(v) for v in text.split(",") if v]


def parse_assignments(items: list[str]) -> dict:
    """``["a=1", "b=(0.1, 0.01)", "c=name"]`` → keywords: each value a Python literal where it
    reads as one, else the text itself."""
    out = {}
    for item in items:
        key, _, text = item.partition("=")
        try:
            out[key] = ast.literal_eval(text)
        except (ValueError, SyntaxError):
            out[key] = text
    return out


def step_ms(run, q: float) -> float:
    """The ``q``-th percentile of a run's per-step times (``run.step_times_s``), in ms."""
    import numpy as np

    return 1e3 * float(np.percentile(run.step_times_s, q))


def print_table_head(*columns: str) -> None:
    """The head of a Markdown table: its column names, then the ``|---|`` rule."""
    print("| " + " | ".join(columns) + " |")
    print("|" + "---|" * len(columns))


def print_table_row(*cells) -> None:
    """One row of a Markdown table, printed at once (a long benchmark shows its progress)."""
    print("| " + " | ".join(str(cell) for cell in cells) + " |", flush=True)


def parse_folder_and_parts(doc: str, argv, choices: tuple[str, ...], default: str, choose: str):
    """The command line of a study of an MRCLAM folder: ``FOLDER [PART ...] [--json FILE]``, every
    part in ``choices`` when none is named (``default`` says so in the help), an unknown one an
    error ending in ``choose``. Returns the parser (for further errors), the arguments and the parts."""
    import argparse

    parser = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("folder", help="an MRCLAM dataset folder")
    parser.add_argument("parts", nargs="*", metavar="|".join(choices), help=f"what to run (default: {default})")
    parser.add_argument("--json", default=None, metavar="FILE", help="write every figure here")
    args = parser.parse_args(argv)
    parts = args.parts or list(choices)
    unknown = sorted(set(parts) - set(choices))
    if unknown:
        parser.error(f"unknown part(s) {', '.join(unknown)}: {choose}")
    return parser, args, parts


def write_json(path, result) -> None:
    """``result`` as indented JSON (one value a line where short) to ``path``, if a path is given."""
    import json

    if path:
        Path(path).write_text(json.dumps(result, indent=1) + "\n", encoding="utf-8")

#!/usr/bin/env python3
"""Rerun every number README.md and docs/*.md quote that a script can recompute, and print
quoted vs measured. Exit status 1 when a number does not match (or its text is no longer in
the doc), 0 otherwise.

Run it from the repository root, as a module (the root is then on the import path, so the
packages and the scripts it calls import without any path manipulation):

    python -m scripts.check_doc_numbers                    # cheap and slow sources (a few minutes)
    python -m scripts.check_doc_numbers --cheap            # only the cheap ones (under a minute)
    python -m scripts.check_doc_numbers --long             # also the long experiments (seed sweeps)
    python -m scripts.check_doc_numbers --shared ../shared # also the numbers measured on the shared data
    python -m scripts.check_doc_numbers --source grid200   # one source (repeatable)
    python -m scripts.check_doc_numbers --list             # the registry, without running anything

The registry is scripts/doc_numbers/registry/ (one module per doc): each entry is the doc, the
exact text that holds the number, the measurement (scripts/doc_numbers/sources/) and the tolerance (by
default half a unit of the last quoted digit). Numbers that need the shared data folder
(real datasets that are not shipped) are skipped, with the reason, unless --shared is given.
Times are never registered: they depend on the machine.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

from scripts.doc_numbers.quotes import ROOT, Checker, Context, format_outcomes
from scripts.doc_numbers.registry import QUOTES
from scripts.doc_numbers.sources import SOURCES


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cheap", action="store_true", help="only the cheap sources")
    parser.add_argument("--long", action="store_true", help="also the long sources (tens of minutes)")
    parser.add_argument("--shared", type=Path, default=None, metavar="FOLDER",
                        help="the shared data folder (e.g. ../shared): also the numbers measured on it")
    parser.add_argument("--source", action="append", default=None, metavar="NAME",
                        help="only this source (repeatable); --list shows the names")
    parser.add_argument("--list", action="store_true", help="print the registry and exit")
    args = parser.parse_args(argv)

    sources = {s.name: s for s in SOURCES}
    unknown = [name for name in args.source or [] if name not in sources]
    if unknown:
        parser.error(f"unknown source {', '.join(unknown)}; choose from {', '.join(sources)}")
    if args.shared is not None and not args.shared.is_dir():
        parser.error(f"--shared {args.shared}: no such folder")
    quotes = [q for q in QUOTES if args.source is None or q.source in args.source]
    if args.list:
        for q in quotes:
            s = sources[q.source]
            print(f"{q.doc}: {q.number} ({q.label}) <- {s.name} [{s.cost}{', shared' if s.shared else ''}]: {s.command}")
        print(f"{len(quotes)} quotes from {len({q.source for q in quotes})} sources")
        return 0
    costs = ("cheap",) if args.cheap else ("cheap", "slow", "long") if args.long else ("cheap", "slow")
    if args.source is not None:
        costs = ("cheap", "slow", "long")  # a source asked for by name runs whatever it costs
    with tempfile.TemporaryDirectory(prefix="doc_numbers_") as scratch:
        shared = args.shared.resolve() if args.shared is not None else None
        checker = Checker(sources, Context(ROOT, shared, Path(scratch)), costs)
        outcomes = [checker.check(q) for q in quotes]
    print(format_outcomes(outcomes, sources))
    print("time per source: " + ", ".join(f"{name} {s:.1f} s" for name, s in checker.seconds.items()))
    for name, error in checker.errors.items():
        print(f"\n{name} failed:\n{error}", file=sys.stderr)
    return 1 if any(o.failed for o in outcomes) else 0


if __name__ == "__main__":
    sys.exit(main())

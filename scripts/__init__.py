"""The lab: benchmarks, measurements and tools that stand beside the product, not in it.

Each module is a command, run from the repository's root as ``python -m scripts.NAME``
(``--help`` says what it measures and how long it takes). What several share (BLAS on one
thread, the data paths, seed and keyword parsers) is :mod:`scripts.common`; one script uses
another's public functions by importing it (``from scripts.bench_online import logs``), never
by editing the import path. ``scripts.check_doc_numbers`` (with :mod:`scripts.doc_numbers`) reruns
the numbers README.md and docs/*.md quote; one-off experiments whose numbers the docs still
quote are in :mod:`scripts.experiments`, whose README lists every experiment kept or deleted.
"""

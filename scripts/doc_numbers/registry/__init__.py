"""The numbers README.md and docs/*.md quote that a script can recompute, one module per doc.

Each quote names the doc, the exact text that holds the number, the source that measures it
(:mod:`doc_numbers.sources`) and how to read the number from the source's result. Times are
not registered: they depend on the machine and its load, and the docs say so where they
quote them.
"""

from __future__ import annotations

from doc_numbers.quotes import Quote
from doc_numbers.registry import camera, estimators, live, mrclam_consistency, plaza, readme, seeds

QUOTES: list[Quote] = [*readme.QUOTES, *seeds.QUOTES, *estimators.QUOTES, *camera.QUOTES, *plaza.QUOTES,
                      *live.QUOTES, *mrclam_consistency.QUOTES]

"""The numbers README.md and docs/*.md quote that a script can recompute, one module per doc
(``readme`` holds the numbers README.md quoted before it became a manual: most of them are
now in docs/results.md and docs/output.md; each quote names the doc it is in today).

Each quote names the doc, the exact text that holds the number, the source that measures it
(:mod:`scripts.doc_numbers.sources`) and how to read the number from the source's result. Times are
not registered: they depend on the machine and its load, and the docs say so where they
quote them.
"""

from __future__ import annotations

from scripts.doc_numbers.quotes import Quote
from scripts.doc_numbers.registry import (camera, estimators, live, mrclam_consistency, plaza, readme, seeds,
                                          stereo_covariance)

QUOTES: list[Quote] = [*readme.QUOTES, *seeds.QUOTES, *estimators.QUOTES, *camera.QUOTES, *plaza.QUOTES,
                      *live.QUOTES, *mrclam_consistency.QUOTES, *stereo_covariance.QUOTES]

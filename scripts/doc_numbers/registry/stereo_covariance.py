"""docs/results-seed003.md's table of the 3-D estimators told the true 4×4 stereo pixel
covariance, its diagonal or one σ (``scripts/stereo_pixel_covariance.py``)."""

from __future__ import annotations

from scripts.doc_numbers.quotes import Quote, numbers_in, row

DOC = "docs/results-seed003.md"

#: The table's rows as the doc prints them (told, estimator, ATE, NEES in band %, NEES mean, NIS).
ROWS = (
    "| true | ekf-vio | 0.404 | 53 | 19.6 | 3.97 |",
    "| true | ekf-vio-fej | 0.348 | 99 | 5.5 | 3.98 |",
    "| true | isam2-3d | 0.168 | 99 | 4.2 | – |",
    "| diagonal | ekf-vio | 0.463 | 31 | 26.9 | 3.65 |",
    "| diagonal | ekf-vio-fej | 0.352 | 97 | 5.9 | 3.65 |",
    "| diagonal | isam2-3d | 0.188 | 99 | 5.2 | – |",
    "| isotropic | ekf-vio | 0.641 | 31 | 25.6 | 3.08 |",
    "| isotropic | ekf-vio-fej | 0.351 | 97 | 6.4 | 3.09 |",
    "| isotropic | isam2-3d | 0.173 | 98 | 7.3 | – |",
)
COLUMNS = (("ate_rmse_m", 1.0), ("nees_inside_95", 100.0), ("nees_mean", 1.0), ("nis_mean", 1.0))


def _reader(told: str, name: str, key: str, scale: float):
    return lambda result: scale * result[told][name][key]


def _quotes(text: str) -> list[Quote]:
    told, name = (cell.strip() for cell in text.strip("|").split("|")[:2])
    first = len(numbers_in(f"| {told} | {name} |"))  # isam2-3d's own digit comes first
    columns = COLUMNS if name != "isam2-3d" else COLUMNS[:3]
    cells = {first + i: _reader(told, name, key, scale) for i, (key, scale) in enumerate(columns)}
    return row(DOC, text, "stereo-pixel-covariance", f"pixel covariance, {told} {name}", cells)


QUOTES: list[Quote] = [quote for text in ROWS for quote in _quotes(text)]

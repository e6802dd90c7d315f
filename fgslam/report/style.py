"""What every figure of the report shares: the off-screen Agg canvas, the colours and
markers, saving a PNG, which runs a figure draws (baselines faint, left out or shown, see
:mod:`fgslam.report`), and each run's final trajectory moved by the alignment it was measured with.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from fgslam.atomic import save_figure
from fgslam.compare import EstimatorRun, Reference, apply_se2, estimator_alignment


_FIGSIZE_IN = (9.0, 6.0)
_DPI = 100
_COLOURS = ["#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf"]
_MARKERS = ["o", "^", "s", "D", "v", "P", "X", "h"]

#: Estimators drawn as a baseline (faint, or left out) rather than as a competitor.
BASELINE_ESTIMATORS = frozenset({"dead_reckoning"})
#: What the figures do with a baseline: draw it faint and zoom to the others, leave it out,
#: or draw it like any estimator.
BASELINE_MODES = ("fade", "drop", "show")
_FAINT_ALPHA = 0.3


def _new_figure() -> Figure:
    fig = Figure(figsize=_FIGSIZE_IN, dpi=_DPI, layout="constrained")
    FigureCanvasAgg(fig)  # attaches the Agg canvas: off-screen rendering only
    return fig


def _style(i: int) -> tuple[str, str]:
    return _COLOURS[i % len(_COLOURS)], _MARKERS[i % len(_MARKERS)]


def _legend_and_save(fig: Figure, ax, path, with_legend: bool = True, **legend) -> Path:
    """Legend outside the axes on the right, then the PNG (no software tag, optimised)."""
    if with_legend:
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False, **legend)
    return save_figure(fig, path, dpi=_DPI, metadata={"Software": None}, pil_kwargs={"optimize": True})


def _aligned_final(run: EstimatorRun, reference: Reference) -> tuple[np.ndarray, bool, float, np.ndarray]:
    aligned, rot, trans = estimator_alignment(run, reference)
    final = np.asarray(run.final, dtype=float).reshape(-1, 3)
    return (apply_se2(final, rot, trans) if len(final) else final), aligned, rot, trans


def _landmark_array(landmarks: dict | None) -> np.ndarray:
    if not landmarks:
        return np.zeros((0, 2))
    return np.array([landmarks[k] for k in sorted(landmarks)], dtype=float).reshape(-1, 2)


def _is_baseline(run: EstimatorRun, baselines) -> bool:
    return run.name in baselines


def _is_the_reference(name: str, reference: Reference) -> bool:
    """Whether the estimator ``name`` is what the figures measure against: the batch, when
    the reference is the smoothed solution (no ground truth)."""
    return name == "batch" and reference.kind == "smoothed"


def _plotted(runs: list[EstimatorRun], baselines, baseline: str) -> list[tuple[int, EstimatorRun, bool]]:
    """``(colour index, run, is_baseline)`` for every run a figure draws: the colour index is
    the run's place in ``runs`` (the same colour in every figure whatever is dropped), and
    baselines are left out when ``baseline == "drop"``. A baseline is drawn faint when
    ``baseline == "fade"`` and like any estimator when ``"show"``."""
    if baseline not in BASELINE_MODES:
        raise ValueError(f"baseline must be one of {', '.join(BASELINE_MODES)}, not {baseline!r}")
    out = []
    for i, run in enumerate(runs):
        is_base = _is_baseline(run, baselines) and baseline != "show"
        if is_base and baseline == "drop":
            continue
        out.append((i, run, is_base))
    return out


def _faint(label: str) -> str:
    return f"{label} (baseline: faint, clipped)"

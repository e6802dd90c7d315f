"""The figures of ``fgslam bench``: average NEES per step and the ATE over the Monte Carlo runs."""

from __future__ import annotations

import os
from pathlib import Path

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from fgslam.atomic import save_figure


def write_monte_carlo_figures(out_dir: str | os.PathLike[str], result) -> list[str]:
    """``nees.png`` (average NEES per step with its χ² band, per estimator) and ``ate.png``
    (box plots of the final and online ATE over the runs) for a
    :class:`fgslam.montecarlo.MonteCarloResult`; returns the file names written."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    names = list(result.average_nees)
    low, high = result.band

    fig = Figure(figsize=(8, 4))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    for name in names:
        ax.plot(result.average_nees[name], lw=1, label=f"{name} ({100 * result.share_inside(name):.0f} % inside)")
    ax.axhline(low, color="k", ls="--", lw=0.8, label=f"95 % band [{low:.2f}, {high:.2f}]")
    ax.axhline(high, color="k", ls="--", lw=0.8)
    ax.axhline(float(result.dof), color="0.6", ls=":", lw=0.8)
    ax.set_xlabel("step")
    ax.set_ylabel(f"average NEES over {len(result.runs)} runs")
    ax.set_title(f"{result.scenario}: NEES of the online pose ({result.dof} DoF)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, out / "nees.png", dpi=110)

    fig = Figure(figsize=(8, 4))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    data, labels = [], []
    for name in names:
        for kind, values in (("final", "ate_final_m"), ("online", "ate_online_m")):
            data.append([getattr(r, values)[name] for r in result.runs])
            labels.append(f"{name}\n{kind}")
    ax.boxplot(data)
    ax.set_xticks(range(1, len(labels) + 1), labels)
    ax.set_ylabel("ATE (m)")
    ax.set_title(f"{result.scenario}: ATE over {len(result.runs)} runs")
    fig.tight_layout()
    save_figure(fig, out / "ate.png", dpi=110)
    return ["nees.png", "ate.png"]

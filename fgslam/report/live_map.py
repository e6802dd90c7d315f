"""The map of ``fgslam live --map-png``: the trajectory so far, the landmarks and the waypoints."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from fgslam.report.style import _COLOURS


def plot_live_map(path, trajectory, landmarks: dict, waypoints=None) -> Path:
    """The live loop's map so far (``fgslam live --map-png``): iSAM2's trajectory, its
    landmarks with their ids, and the waypoints. Written to a temporary file and renamed,
    so a viewer never sees half a picture."""
    fig = Figure(figsize=(6, 6), dpi=80)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    traj = np.asarray(trajectory, dtype=float).reshape(-1, 3)
    if waypoints is not None:
        w = np.asarray(waypoints, dtype=float).reshape(-1, 2)
        ax.plot(w[:, 0], w[:, 1], "o--", color="0.6", lw=0.8, ms=4, label="waypoints")
    if len(traj):
        ax.plot(traj[:, 0], traj[:, 1], color=_COLOURS[1], lw=1.2, label="iSAM2 trajectory")
        ax.plot(traj[-1, 0], traj[-1, 1], marker=(3, 0, np.degrees(traj[-1, 2]) - 90), ms=12, color=_COLOURS[1])
    for lid, (x, y) in sorted(landmarks.items()):
        ax.plot(x, y, "s", color=_COLOURS[0], ms=6)
        ax.annotate(str(lid), (x, y), textcoords="offset points", xytext=(4, 4), fontsize=8)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"fgslam live: {len(traj)} poses, {len(landmarks)} landmarks", fontsize=10)
    ax.grid(True, lw=0.5, alpha=0.5)
    ax.legend(loc="upper right", fontsize=8)
    out = Path(path)
    tmp = out.with_name(out.name + ".tmp.png")
    fig.savefig(tmp)
    os.replace(tmp, out)
    return out

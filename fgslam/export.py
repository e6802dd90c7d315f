"""Export the factor graph as a g2o file, for g2o, its viewer and other tools that read it.

gtsam's own ``writeG2o`` drops bearing-range factors, so this writes every edge itself:

* ``VERTEX_SE2 i x y θ`` — pose ``i`` (vertex id = pose index);
* ``VERTEX_XY v x y`` — a point landmark; ``VERTEX_SE2 v x y θ`` — a tag (``isam2-tags``);
  vertex id v = number of poses + landmark id, so ids never collide;
* ``EDGE_SE2 i j dx dy dθ I11 I12 I13 I22 I23 I33`` — odometry (and a tag's relative pose):
  the measured increment and the upper triangle of its information matrix, the inverse of
  the covariance of GTSAM's ``BetweenFactorPose2``. g2o's SE2 edge error
  ``t2v(Z⁻¹ · (Xᵢ⁻¹ · Xⱼ))`` has the same (x, y, θ) order and frame, so the matrix carries
  over unchanged;
* ``EDGE_SE2_XY i v x y I11 I12 I22`` — a bearing-range observation, as g2o's point
  measurement in the robot frame: (r·cos b, r·sin b), with the information of the
  first-order propagated covariance J·diag(σ_r², σ_b²)·Jᵀ, J = ∂(x, y)/∂(r, b);
* ``FIX 0`` — the prior on pose 0 (g2o holds that vertex fixed).

Not expressible in standard g2o and therefore written as ``#`` comment lines at the end of
the file (``gtsam.readG2o`` stops reading edges after a leading comment): robust kernels
(the Gaussian part of each edge is written; the kernel is named in a comment), landmark
heights (``PriorFactorDouble``) and bearing-range observations of a tag (an SE2 vertex,
which ``EDGE_SE2_XY`` cannot reach).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import gtsam
import numpy as np

__all__ = ["format_g2o", "write_g2o", "landmark_vertex_id"]


def landmark_vertex_id(num_poses: int, landmark_id: int) -> int:
    """The g2o vertex id of landmark ``landmark_id`` in a graph with ``num_poses`` poses."""
    return num_poses + int(landmark_id)


def _symbol(key: int) -> tuple[str, int]:
    s = gtsam.Symbol(key)
    return chr(s.chr()), int(s.index())


def _gaussian_covariance(noise) -> tuple[np.ndarray, str | None]:
    """The Gaussian covariance of a noise model, and the robust kernel's name if it has one."""
    if isinstance(noise, gtsam.noiseModel.Robust):
        return np.asarray(noise.noise().covariance(), dtype=float), type(noise.robust()).__name__
    return np.asarray(noise.covariance(), dtype=float), None


def _upper(information: np.ndarray) -> str:
    n = information.shape[0]
    return " ".join(f"{information[i, j]:.17g}" for i in range(n) for j in range(i, n))


def format_g2o(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, num_poses: int) -> str:
    """The g2o text of ``graph`` at ``values`` (poses ``X(0..num_poses-1)``, landmarks ``L``/``T``)."""
    vertices: list[str] = []
    for i in range(num_poses):
        p = values.atPose2(gtsam.symbol("x", i))
        vertices.append(f"VERTEX_SE2 {i} {p.x():.17g} {p.y():.17g} {p.theta():.17g}")
    landmark_lines: dict[int, str] = {}
    edges: list[str] = []
    notes: list[str] = []

    def vertex(key: int) -> int:
        kind, index = _symbol(key)
        if kind == "x":
            return index
        vid = landmark_vertex_id(num_poses, index)
        if vid not in landmark_lines:
            if kind == "t":
                p = values.atPose2(key)
                landmark_lines[vid] = f"VERTEX_SE2 {vid} {p.x():.17g} {p.y():.17g} {p.theta():.17g}"
            else:
                p = values.atPoint2(key)
                landmark_lines[vid] = f"VERTEX_XY {vid} {p[0]:.17g} {p[1]:.17g}"
        return vid

    fixed = []
    for n in range(graph.size()):
        factor = graph.at(n)
        keys = list(factor.keys())
        if isinstance(factor, gtsam.PriorFactorPose2):
            kind, index = _symbol(keys[0])
            fixed.append(f"FIX {index}")
            continue
        if isinstance(factor, gtsam.BetweenFactorPose2):
            cov, kernel = _gaussian_covariance(factor.noiseModel())
            z = factor.measured()
            edge = f"EDGE_SE2 {vertex(keys[0])} {vertex(keys[1])}"
            edges.append(f"{edge} {z.x():.17g} {z.y():.17g} {z.theta():.17g} {_upper(np.linalg.inv(cov))}")
        elif isinstance(factor, gtsam.BearingRangeFactor2D):
            cov, kernel = _gaussian_covariance(factor.noiseModel())  # (bearing, range) order
            m = factor.measured()
            b, r = m.bearing().theta(), m.range()
            J = np.array([[-r * math.sin(b), math.cos(b)], [r * math.cos(b), math.sin(b)]])  # ∂(x, y)/∂(b, r)
            xy_cov = J @ cov @ J.T
            edge = f"EDGE_SE2_XY {vertex(keys[0])} {vertex(keys[1])}"
            edges.append(
                f"{edge} {r * math.cos(b):.17g} {r * math.sin(b):.17g} {_upper(np.linalg.inv(xy_cov))}"
            )
        else:
            kinds = ", ".join(f"{k}{i}" for k, i in map(_symbol, keys))
            notes.append(f"# not in g2o: {type(factor).__name__} on {kinds}")
            continue
        if kernel is not None:
            notes.append(f"# robust kernel {kernel} on the edge {edge} (written with its Gaussian part)")
    header = [
        "# fgslam factor graph (g2o 2-D). Pose vertices 0..{} are the log's poses; landmark "
        "vertex = {} + landmark id.".format(num_poses - 1, num_poses)
    ]
    # Comments go last: gtsam.readG2o stops reading edges after a leading comment line.
    body = vertices + [landmark_lines[v] for v in sorted(landmark_lines)] + edges + fixed + header + notes
    return "\n".join(body) + "\n"


def write_g2o(path: str | os.PathLike[str], graph: gtsam.NonlinearFactorGraph, values: gtsam.Values,
              num_poses: int) -> None:
    """Write :func:`format_g2o` to ``path`` (overwriting it)."""
    Path(path).write_text(format_g2o(graph, values, num_poses), encoding="utf-8")

"""Export the factor graph as a g2o file that g2o's tools and ``gtsam.readG2o`` both read.

gtsam's own ``writeG2o`` drops bearing-range factors, so this writes every edge itself:

* ``VERTEX_SE2 i x y θ`` — pose ``i`` (vertex id = pose index);
* ``VERTEX_XY v x y`` — a point landmark; ``VERTEX_SE2 v x y θ`` — a tag (``isam2-tags``);
  vertex id v = number of poses + landmark id, so ids never collide;
* ``EDGE_SE2 i j dx dy dθ I11 I12 I13 I22 I23 I33`` — odometry (and a tag's relative pose):
  the measured increment and the upper triangle of its information matrix, the inverse of
  the covariance of GTSAM's ``BetweenFactorPose2``. g2o's SE2 edge error
  ``t2v(Z⁻¹ · (Xᵢ⁻¹ · Xⱼ))`` has the same (x, y, θ) order and frame, so the matrix carries
  over unchanged;
* each bearing-range observation twice, once for each reader (each reader skips the other's
  line, so neither counts an observation twice):

  - ``EDGE_SE2_XY i v x y I11 I12 I22`` — for g2o: the point measured in the robot frame,
    (r·cos b, r·sin b), with the information of the first-order propagated covariance
    J·diag(σ_r², σ_b²)·Jᵀ, J = ∂(x, y)/∂(r, b). ``gtsam.readG2o`` ignores this tag;
  - ``BR i v b r σ_b σ_r`` — for GTSAM: the measurement and noise exactly as our
    ``BearingRangeFactor2D`` holds them; ``gtsam.readG2o`` makes it
    ``BearingRangeFactor2D(i, L(v))`` (its ``VERTEX_XY v`` is ``L(v)`` too). g2o has no such
    type and skips those lines (older builds print ``unknown type: BR`` once);
* ``FIX 0`` — the prior on pose 0 (g2o holds that vertex fixed); its mean and covariance are
  given in a comment for GTSAM, whose reader has no line for a prior (the only factor
  ``gtsam.readG2o`` does not return: add ``PriorFactorPose2(0, …)`` from that comment).

Everything after the factor lines: with gtsam 4.3, a line whose tag is not followed by two
integers (``FIX 0``, ``# a comment``; ``FOO 1 2`` is harmless) silently ends
``gtsam.readG2o``'s reading of factors (measured: a comment before the first edge leaves 0
factors), so ``FIX`` and every ``#`` line come last. The comments name what
standard g2o cannot express: robust kernels (the Gaussian part of each edge is written; the
kernel is named), landmark heights (``PriorFactorDouble``), range-only observations and
bearing-range observations of a tag (an SE2 vertex, which neither ``EDGE_SE2_XY`` nor
``BR`` can reach).
"""

from __future__ import annotations

import math
import os

import gtsam
import numpy as np

from fgslam.atomic import write_text_whole

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
            cov, kernel = _gaussian_covariance(factor.noiseModel())
            p = factor.prior()
            notes.append(
                f"# prior PriorFactorPose2 on vertex {index} (FIX {index} above): mean {p.x():.17g} {p.y():.17g} "
                f"{p.theta():.17g} covariance {_upper(cov)}"
            )
            if kernel is not None:
                notes.append(f"# robust kernel {kernel} on the prior of vertex {index}")
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
            i, v = vertex(keys[0]), vertex(keys[1])
            edge = f"EDGE_SE2_XY {i} {v}"
            edges.append(
                f"{edge} {r * math.cos(b):.17g} {r * math.sin(b):.17g} {_upper(np.linalg.inv(xy_cov))}"
            )
            # the same observation for gtsam.readG2o: bearing, range and their standard deviations
            sigma_b, sigma_r = math.sqrt(cov[0, 0]), math.sqrt(cov[1, 1])
            edges.append(f"BR {i} {v} {b:.17g} {r:.17g} {sigma_b:.17g} {sigma_r:.17g}")
            if cov[0, 1] != 0.0:
                notes.append(f"# BR {i} {v} carries only the diagonal of its (bearing, range) covariance "
                             f"(off-diagonal {cov[0, 1]:.17g}); EDGE_SE2_XY {i} {v} carries all of it")
        else:
            kinds = ", ".join(f"{k}{i}" for k, i in map(_symbol, keys))
            notes.append(f"# not in g2o nor gtsam.readG2o: {type(factor).__name__} on {kinds}")
            continue
        if kernel is not None:
            notes.append(f"# robust kernel {kernel} on the edge {edge} (written with its Gaussian part)")
    header = [
        "# fgslam factor graph (g2o 2-D). Pose vertices 0..{} are the log's poses; landmark "
        "vertex = {} + landmark id.".format(num_poses - 1, num_poses),
        "# Each bearing-range observation is written twice: EDGE_SE2_XY for g2o (gtsam.readG2o "
        "skips it) and BR for gtsam.readG2o (g2o skips it: unknown type BR).",
    ]
    # FIX and comments go last: gtsam.readG2o stops reading factors at the first line whose
    # tag is not followed by two integers.
    body = vertices + [landmark_lines[v] for v in sorted(landmark_lines)] + edges + fixed + header + notes
    return "\n".join(body) + "\n"


def write_g2o(path: str | os.PathLike[str], graph: gtsam.NonlinearFactorGraph, values: gtsam.Values,
              num_poses: int) -> None:
    """Write :func:`format_g2o` to ``path`` (replacing it), whole or not at all (:mod:`fgslam.atomic`)."""
    write_text_whole(path, format_g2o(graph, values, num_poses))

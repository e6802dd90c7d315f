"""g2o export (fgslam/export.py), checked with an independent parser and GTSAM's own reader."""

from __future__ import annotations

import math

import gtsam
import numpy as np
import pytest

from builders import run_smoother
from fgslam.cli import main
from fgslam.export import format_g2o, landmark_vertex_id
from fgslam.smoother import odometry_noise_covariance
from slamio.log import group_steps
from slamio.sim import simulate


def parse_g2o(text: str) -> dict[str, list[list[str]]]:
    """Lines by their first word (comments under "#")."""
    out: dict[str, list[list[str]]] = {}
    for line in text.splitlines():
        words = line.split()
        if words:
            out.setdefault("#" if words[0].startswith("#") else words[0], []).append(words)
    return out


def upper_to_matrix(values, n):
    M = np.zeros((n, n))
    it = iter(float(v) for v in values)
    for i in range(n):
        for j in range(i, n):
            M[i, j] = M[j, i] = next(it)
    return M


@pytest.fixture(scope="module")
def octagon():
    header, records = simulate("arena-octagon", 1, laps=1)
    steps = group_steps(header, records)
    smoother = run_smoother(header, steps)
    return steps, smoother, format_g2o(smoother.graph(), smoother.estimate(), smoother.num_poses)


def test_vertices_are_the_estimate(octagon):
    steps, smoother, text = octagon
    g2o = parse_g2o(text)
    n = len(steps)
    poses = {int(w[1]): [float(v) for v in w[2:]] for w in g2o["VERTEX_SE2"]}
    assert sorted(poses) == list(range(n))
    assert np.allclose([poses[i] for i in range(n)], smoother.trajectory(), atol=1e-12)
    points = {int(w[1]): [float(v) for v in w[2:]] for w in g2o["VERTEX_XY"]}
    for lid, xy in smoother.landmarks().items():
        assert np.allclose(points[landmark_vertex_id(n, lid)], xy, atol=1e-12)
    assert g2o["FIX"] == [["FIX", "0"]]


def test_edges_carry_the_log_measurements_and_informations(octagon):
    steps, _, text = octagon
    g2o = parse_g2o(text)
    n = len(steps)
    odometry = {(int(w[1]), int(w[2])): w for w in g2o["EDGE_SE2"]}
    assert len(odometry) == n - 1
    for s in steps[1:]:
        w = odometry[(s.index - 1, s.index)]
        o = s.odometry
        assert [float(v) for v in w[3:6]] == pytest.approx([o.dx_m, o.dy_m, o.dtheta_rad], abs=1e-15)
        assert np.allclose(upper_to_matrix(w[6:], 3), np.linalg.inv(odometry_noise_covariance(o)), rtol=1e-9)
    points = g2o["EDGE_SE2_XY"]
    observations = [(s.index, o) for s in steps for o in s.observations]
    assert len(points) == len(observations)
    for w, (k, o) in zip(points, observations):  # written in the graph's order: the log's
        assert (int(w[1]), int(w[2])) == (k, landmark_vertex_id(n, o.landmark_id))
        r, b = o.range_m, o.bearing_rad
        assert [float(v) for v in w[3:5]] == pytest.approx([r * math.cos(b), r * math.sin(b)], abs=1e-12)
        J = np.array([[math.cos(b), -r * math.sin(b)], [math.sin(b), r * math.cos(b)]])  # ∂(x, y)/∂(r, b)
        expected = np.linalg.inv(J @ np.diag([o.sigma_range_m**2, o.sigma_bearing_rad**2]) @ J.T)
        assert np.allclose(upper_to_matrix(w[5:], 2), expected, rtol=1e-9)


def test_gtsams_reader_sees_the_same_odometry_graph(octagon, tmp_path):
    steps, smoother, text = octagon
    path = tmp_path / "graph.g2o"
    path.write_text(text)
    graph, values = gtsam.readG2o(str(path), False)  # reads the SE2 part, drops EDGE_SE2_XY
    ours = smoother.graph()
    odometry_error = sum(
        ours.at(i).error(smoother.estimate()) for i in range(ours.size()) if isinstance(ours.at(i), gtsam.BetweenFactorPose2)
    )
    assert graph.size() == len(steps) - 1
    assert graph.error(values) == pytest.approx(odometry_error, rel=1e-9)


def test_robust_kernels_heights_and_tags_are_said(tmp_path):
    header, records = simulate("cylinders", 1, laps=1)
    smoother = run_smoother(header, group_steps(header, records), robust="cauchy")
    text = format_g2o(smoother.graph(), smoother.estimate(), smoother.num_poses)
    comments = "\n".join(" ".join(w) for w in parse_g2o(text)["#"])
    assert "robust kernel Cauchy" in comments and "PriorFactorDouble" in comments
    header, records = simulate("arena-octagon", 1, laps=1)
    steps = group_steps(header, records)
    tags = run_smoother(header, steps, tags=True)
    g2o = parse_g2o(format_g2o(tags.graph(), tags.estimate(), tags.num_poses))
    tag_vertices = [int(w[1]) for w in g2o["VERTEX_SE2"] if int(w[1]) >= len(steps)]
    assert sorted(tag_vertices) == [landmark_vertex_id(len(steps), i) for i in sorted(tags.landmark_yaws())]
    assert "VERTEX_XY" not in g2o and "EDGE_SE2_XY" not in g2o


def test_fgslam_run_writes_the_graph(tmp_path, capsys):
    log = tmp_path / "sq.jsonl"
    assert main(["sim", "arena-square", "--seed", "2", "--laps", "1", "--out", str(log)]) == 0
    assert main(["run", str(log), "--out", str(tmp_path / "r"), "--no-report"]) == 0
    assert "graph.g2o" in capsys.readouterr().out
    g2o = parse_g2o((tmp_path / "r" / "graph.g2o").read_text())
    assert len(g2o["EDGE_SE2_XY"]) > 0 and len(g2o["EDGE_SE2"]) == len(g2o["VERTEX_SE2"]) - 1

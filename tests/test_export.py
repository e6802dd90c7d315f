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


def _prior_from_comment(text: str):
    """The prior on pose 0 as the file's comment states it: ``(vertex, mean, covariance)``."""
    line = next(line for line in text.splitlines() if line.startswith("# prior PriorFactorPose2"))
    words = line.split()
    vertex = int(words[words.index("vertex") + 1])
    at = words.index("mean")
    mean = [float(v) for v in words[at + 1 : at + 4]]
    covariance = upper_to_matrix(words[words.index("covariance") + 1 :], 3)
    return vertex, mean, covariance


def _our_key_to_file_key(key: int, num_poses: int) -> int:
    """X(i) -> i and L(id) -> L(num_poses + id): the keys gtsam.readG2o gives the file's vertices."""
    s = gtsam.Symbol(key)
    if chr(s.chr()) == "x":
        return int(s.index())
    return gtsam.symbol("l", landmark_vertex_id(num_poses, int(s.index())))


def test_gtsams_reader_gets_every_factor_back(octagon, tmp_path):
    """gtsam.readG2o on the file returns every factor of our graph but the prior (FIX 0, which
    its reader has no line for), in our order, with our measurements and noise."""
    steps, smoother, text = octagon
    path = tmp_path / "graph.g2o"
    path.write_text(text)
    graph, values = gtsam.readG2o(str(path), False)
    ours = smoother.graph()
    n = smoother.num_poses
    ours_kinds = [type(ours.at(i)).__name__ for i in range(ours.size())]
    assert ours_kinds.count("PriorFactorPose2") == 1
    ours_factors = [ours.at(i) for i in range(ours.size()) if not isinstance(ours.at(i), gtsam.PriorFactorPose2)]
    assert graph.size() == ours.size() - 1 == len(ours_factors)
    assert ours_kinds.count("BearingRangeFactor2D") == len([o for s in steps for o in s.observations]) > 0
    landmarks = smoother.landmarks()
    assert values.size() == n + len(landmarks)
    for k, mine in enumerate(ours_factors):
        theirs = graph.at(k)
        assert type(theirs) is type(mine)
        assert list(theirs.keys()) == [_our_key_to_file_key(key, n) for key in mine.keys()]
        if isinstance(mine, gtsam.BearingRangeFactor2D):
            a, b = mine.measured(), theirs.measured()
            assert b.range() == a.range()
            assert b.bearing().theta() == pytest.approx(a.bearing().theta(), abs=1e-15)  # Rot2 from its angle
        else:
            a, b = mine.measured(), theirs.measured()
            assert [b.x(), b.y(), b.theta()] == pytest.approx([a.x(), a.y(), a.theta()], abs=1e-15)
        expected = mine.noiseModel().covariance()
        np.testing.assert_allclose(theirs.noiseModel().covariance(), expected, rtol=1e-12,
                                   atol=1e-12 * np.abs(expected).max())  # through the information and back
    # The same total error at the file's vertices (plus the prior, from its comment) as ours.
    vertex, mean, covariance = _prior_from_comment(text)
    assert vertex == 0 and mean == pytest.approx(list(smoother.header.start_pose), abs=1e-15)
    reread = gtsam.NonlinearFactorGraph(graph)
    reread.add(gtsam.PriorFactorPose2(0, gtsam.Pose2(*mean), gtsam.noiseModel.Gaussian.Covariance(covariance)))
    assert reread.error(values) == pytest.approx(ours.error(smoother.estimate()), rel=1e-9)


def test_batch_solution_of_the_reread_graph_is_ours(octagon, tmp_path):
    """Levenberg-Marquardt on the graph gtsam.readG2o returns (plus the stated prior), started
    from the file's vertices moved by seeded noise (iSAM2's estimate in the file may already be
    the optimum), lands on the batch solution of our own graph."""
    steps, smoother, text = octagon
    path = tmp_path / "graph.g2o"
    path.write_text(text)
    graph, values = gtsam.readG2o(str(path), False)
    _, mean, covariance = _prior_from_comment(text)
    graph.add(gtsam.PriorFactorPose2(0, gtsam.Pose2(*mean), gtsam.noiseModel.Gaussian.Covariance(covariance)))
    rng = np.random.default_rng(0)
    for key in values.keys():  # 1 cm and 0.01 rad off, so the solve has to move every pose
        if gtsam.Symbol(key).chr() == 0:  # poses are plain integer keys in a g2o file
            values.update(key, values.atPose2(key).retract(rng.normal(0.0, 0.01, 3)))
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-12)
    params.setAbsoluteErrorTol(1e-12)
    theirs = gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
    ours = gtsam.LevenbergMarquardtOptimizer(smoother.graph(), smoother.estimate(), params).optimize()
    n = smoother.num_poses
    ours_poses = np.array([[p.x(), p.y(), p.theta()] for p in (ours.atPose2(gtsam.symbol("x", i)) for i in range(n))])
    their_poses = np.array([[p.x(), p.y(), p.theta()] for p in (theirs.atPose2(i) for i in range(n))])
    np.testing.assert_allclose(their_poses, ours_poses, atol=1e-7)
    for lid in smoother.landmarks():
        np.testing.assert_allclose(
            theirs.atPoint2(gtsam.symbol("l", landmark_vertex_id(n, lid))), ours.atPoint2(gtsam.symbol("l", lid)),
            atol=1e-7,
        )
    # and the solve moved something: it started away from the optimum
    assert graph.error(values) > graph.error(theirs)


def test_g2o_reads_every_edge(octagon, tmp_path):
    """g2o itself (its official Python bindings, when installed) loads every vertex and edge,
    fixes vertex 0 and skips the BR lines; its optimum is ours to within the linearisation of
    the bearing-range noise into an x-y information."""
    g2o = pytest.importorskip("g2opy")
    steps, smoother, text = octagon
    path = tmp_path / "graph.g2o"
    path.write_text(text)
    optimizer = g2o.SparseOptimizer()
    optimizer.set_algorithm(g2o.OptimizationAlgorithmLevenberg(g2o.BlockSolverX(g2o.LinearSolverEigenX())))
    assert optimizer.load(str(path))
    n = smoother.num_poses
    observations = len([o for s in steps for o in s.observations])
    assert len(optimizer.vertices()) == n + len(smoother.landmarks())
    assert len(optimizer.edges()) == (n - 1) + observations
    assert [v.id() for v in optimizer.vertices().values() if v.fixed()] == [0]
    optimizer.initialize_optimization()
    optimizer.optimize(50)
    ours = gtsam.LevenbergMarquardtOptimizer(smoother.graph(), smoother.estimate(), gtsam.LevenbergMarquardtParams())
    solution = ours.optimize()
    for i in range(n):
        p = solution.atPose2(gtsam.symbol("x", i))
        est = optimizer.vertex(i).estimate()
        assert math.hypot(est.translation()[0] - p.x(), est.translation()[1] - p.y()) < 5e-3


def test_robust_kernels_heights_and_tags_are_said(tmp_path):
    header, records = simulate("cylinders", 1, laps=1)
    smoother = run_smoother(header, group_steps(header, records), robust="cauchy")
    text = format_g2o(smoother.graph(), smoother.estimate(), smoother.num_poses)
    comments = "\n".join(" ".join(w) for w in parse_g2o(text)["#"])
    assert "robust kernel Cauchy" in comments and "PriorFactorDouble" in comments
    # gtsam.readG2o still gets every odometry and bearing-range factor (their Gaussian part)
    path = tmp_path / "robust.g2o"
    path.write_text(text)
    graph, _ = gtsam.readG2o(str(path), False)
    ours = smoother.graph()
    kinds = [type(ours.at(i)).__name__ for i in range(ours.size())]
    assert graph.size() == kinds.count("BetweenFactorPose2") + kinds.count("BearingRangeFactor2D")
    assert kinds.count("BearingRangeFactor2D") > 0
    header, records = simulate("arena-octagon", 1, laps=1)
    steps = group_steps(header, records)
    tags = run_smoother(header, steps, tags=True)
    g2o = parse_g2o(format_g2o(tags.graph(), tags.estimate(), tags.num_poses))
    tag_vertices = [int(w[1]) for w in g2o["VERTEX_SE2"] if int(w[1]) >= len(steps)]
    assert sorted(tag_vertices) == [landmark_vertex_id(len(steps), i) for i in sorted(tags.landmark_yaws())]
    assert "VERTEX_XY" not in g2o and "EDGE_SE2_XY" not in g2o and "BR" not in g2o
    path = tmp_path / "tags.g2o"
    path.write_text(format_g2o(tags.graph(), tags.estimate(), tags.num_poses))
    graph, _ = gtsam.readG2o(str(path), False)  # pose-pose and pose-tag edges: every BetweenFactorPose2
    ours = tags.graph()
    between = sum(isinstance(ours.at(i), gtsam.BetweenFactorPose2) for i in range(ours.size()))
    assert graph.size() == between > len(steps) - 1


def test_fgslam_run_writes_the_graph(tmp_path, capsys):
    log = tmp_path / "sq.jsonl"
    assert main(["sim", "arena-square", "--seed", "2", "--laps", "1", "--out", str(log)]) == 0
    assert main(["run", str(log), "--out", str(tmp_path / "r"), "--no-report"]) == 0
    assert "graph.g2o" in capsys.readouterr().out
    g2o = parse_g2o((tmp_path / "r" / "graph.g2o").read_text())
    assert len(g2o["EDGE_SE2_XY"]) > 0 and len(g2o["EDGE_SE2"]) == len(g2o["VERTEX_SE2"]) - 1
    assert len(g2o["BR"]) == len(g2o["EDGE_SE2_XY"])
    graph, _ = gtsam.readG2o(str(tmp_path / "r" / "graph.g2o"), False)
    assert graph.size() == len(g2o["EDGE_SE2"]) + len(g2o["BR"])

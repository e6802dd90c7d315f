"""The Victoria Park importer (slamio.datasets.victoria_park) on the file gtsam ships.

The oracle is GTSAM's own parser: the factor graph fgslam builds from the imported log must
be, factor by factor, the graph ``gtsam.load2D`` builds from the file (same measurement,
same noise, same error at arbitrary values), apart from the smoother's prior on pose 0.
"""

from __future__ import annotations

import math

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import L, X

from fgslam.smoother import Isam2Smoother, odometry_noise_covariance
from slamio.datasets import DatasetFormatError, default_victoria_park_path, import_victoria_park
from slamio.errors import FgslamError
from builders import assert_log_round_trips
from slamio.log import Observation, Odometry, group_steps


@pytest.fixture(scope="module")
def vp_path() -> str:
    return default_victoria_park_path()


@pytest.fixture(scope="module")
def imported(vp_path):
    return import_victoria_park(vp_path)


@pytest.fixture(scope="module")
def loaded(vp_path):
    return gtsam.load2D(vp_path)


def chain_pose_ids(path: str) -> list[int]:
    """File pose id of each step, read independently of the importer."""
    ids: list[int] = []
    with open(path) as f:
        for line in f:
            t = line.split()
            if t and t[0] == "ODOMETRY":
                if not ids:
                    ids.append(int(t[1]))
                ids.append(int(t[2]))
    return ids


def rotate_back(covariance, dtheta):
    """The covariance a BetweenFactorPose2 gets from a log covariance (smoother's convention)."""
    c, s = math.cos(dtheta), math.sin(dtheta)
    A = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    return A @ np.asarray(covariance) @ A.T


# ----------------------------------------------------------------------------- counts, values


def test_counts_on_the_shipped_file(imported):
    header, records = imported
    odometry = [r for r in records if isinstance(r, Odometry)]
    observations = [r for r in records if isinstance(r, Observation)]
    assert len(odometry) == 6968
    assert len(observations) == 3640
    assert len(records) == 6968 + 3640
    steps = group_steps(header, records)
    assert len(steps) == 6969
    assert len({o.landmark_id for o in observations}) == 151
    assert header.source["poses"] == 6969 and header.source["landmarks"] == 151
    assert header.source["dataset"] == "victoria_park"
    assert header.source["converted_by"] == "fgslam import victoria-park"
    assert header.start_pose == (0.0, 0.0, 0.0)
    assert header.noise["observation"]["lines_with_non_uniform_covariance"] == 0


def test_first_records_equal_the_file_by_hand(imported):
    # line 1  ODOMETRY 0 1 0.000985144 -3.63222e-10 -1.54136e-06 0.0001 0 0 4e-06 0 4e-06
    # lines 2-4 ODOMETRY 1 2 / 2 3 / 3 4 (values below, same noise)
    # line 5  LANDMARK 4 5 11.5387 -3.2007 0.4 0 0.4
    # line 6  ODOMETRY 4 6 0.08819 ...       (pose ids skip 5: it is a landmark id)
    # lines 7-8 ODOMETRY 6 7, 7 8
    # line 9  LANDMARK 8 9 15.2622 4.67917 0.4 0 0.4
    header, records = imported
    expected_odometry = [
        (0.000985144, -3.63222e-10, -1.54136e-06),
        (0.00492658, -1.35875e-08, -6.57618e-06),
        (0.0265992, -4.82655e-07, -4.12159e-05),
        (0.0640488, -2.22135e-06, -8.11689e-05),
    ]
    for k, (record, (dx, dy, dth)) in enumerate(zip(records[:4], expected_odometry), start=1):
        assert isinstance(record, Odometry)
        assert (record.dx_m, record.dy_m, record.dtheta_rad) == (dx, dy, dth)
        assert record.stamp_s == pytest.approx(0.2 * k)
        np.testing.assert_allclose(
            rotate_back(record.covariance, dth), np.diag([1e-4, 4e-6, 4e-6]), rtol=0, atol=1e-18
        )
        assert np.array_equal(record.covariance, np.transpose(record.covariance))

    def check_landmark(record, lid, x, y, stamp):
        assert isinstance(record, Observation)
        assert record.landmark_id == lid
        assert record.range_m == pytest.approx(math.hypot(x, y), rel=1e-15)
        assert record.bearing_rad == pytest.approx(math.atan2(y, x), rel=1e-15)
        assert record.sigma_bearing_rad == pytest.approx(0.2, rel=1e-15)  # sqrt(0.4 / 10)
        assert record.sigma_range_m == pytest.approx(math.sqrt(0.4), rel=1e-15)
        assert record.stamp_s == pytest.approx(stamp)

    check_landmark(records[4], 5, 11.5387, -3.2007, 0.8)  # seen from pose id 4 = step 4
    assert [r.dx_m for r in records[5:8]] == [0.08819, 0.136021, 0.176976]
    check_landmark(records[8], 9, 15.2622, 4.67917, 1.4)  # pose id 8 = step 7
    assert [s.index for s in group_steps(header, records[:9])][-1] == 7


def test_the_log_round_trips(imported, tmp_path):
    header, records = imported
    # reading validates every line (SPD covariances, stamps in order, ...)
    assert_log_round_trips(tmp_path / "vp.jsonl", header, records)


# ----------------------------------------------------------------------------- cross-check with load2D


def perturbed_values(initial: gtsam.Values, seed: int = 7) -> gtsam.Values:
    """load2D's initial values moved at random, so that every factor has a non-zero error."""
    rng = np.random.default_rng(seed)
    out = gtsam.Values()
    for key in initial.keys():
        if gtsam.Symbol(key).chr() == ord("l"):
            out.insert(key, np.asarray(initial.atPoint2(key)) + rng.normal(0.0, 0.5, 2))
        else:
            p = initial.atPose2(key)
            dx, dy, dth = rng.normal(0.0, [0.5, 0.5, 0.05])
            out.insert(key, gtsam.Pose2(p.x() + dx, p.y() + dy, p.theta() + dth))
    return out


def rekeyed(values: gtsam.Values, pose_ids: list[int], n_steps: int) -> gtsam.Values:
    """The same values under fgslam's keys: file pose id pose_ids[k] → X(k), L(id) unchanged."""
    out = gtsam.Values()
    for k in range(n_steps):
        out.insert(X(k), values.atPose2(pose_ids[k]))
    for key in values.keys():
        if gtsam.Symbol(key).chr() == ord("l"):
            out.insert(key, values.atPoint2(key))
    return out


def assert_same_factors(theirs: gtsam.NonlinearFactorGraph, ours: gtsam.NonlinearFactorGraph,
                        key_map: dict[int, int], their_values: gtsam.Values, our_values: gtsam.Values):
    """Factor i of load2D's graph is factor i + 1 of ours (ours starts with the prior)."""
    assert isinstance(ours.at(0), gtsam.PriorFactorPose2)
    assert ours.size() == theirs.size() + 1
    their_errors = np.empty(theirs.size())
    our_errors = np.empty(theirs.size())
    for i in range(theirs.size()):
        a, b = theirs.at(i), ours.at(i + 1)
        assert type(a) is type(b), i
        assert [key_map.get(k, k) for k in a.keys()] == list(b.keys()), i
        if isinstance(a, gtsam.BetweenFactorPose2):
            assert a.measured().equals(b.measured(), 0.0), i
            np.testing.assert_allclose(
                b.noiseModel().covariance(), a.noiseModel().covariance(), rtol=1e-12, atol=1e-20
            )
        else:
            assert isinstance(a, gtsam.BearingRangeFactor2D)
            ma, mb = a.measured(), b.measured()
            assert ma.range() == mb.range(), i
            assert ma.bearing().theta() == mb.bearing().theta(), i
            np.testing.assert_array_equal(a.noiseModel().sigmas(), b.noiseModel().sigmas())
        their_errors[i] = a.error(their_values)
        our_errors[i] = b.error(our_values)
    assert np.all(their_errors > 0.0)  # the perturbation really exercises every factor
    np.testing.assert_allclose(our_errors, their_errors, rtol=1e-9, atol=1e-12)


def direct_graph(header, records) -> gtsam.NonlinearFactorGraph:
    """The graph Isam2Smoother builds (same helpers, same factor order), without running iSAM2."""
    from fgslam.smoother import start_prior_covariance

    graph = gtsam.NonlinearFactorGraph()
    graph.add(gtsam.PriorFactorPose2(
        X(0), gtsam.Pose2(*header.start_pose), gtsam.noiseModel.Gaussian.Covariance(start_prior_covariance(header))
    ))
    for step in group_steps(header, records):
        k = step.index
        if step.odometry is not None:
            o = step.odometry
            graph.add(gtsam.BetweenFactorPose2(
                X(k - 1), X(k), gtsam.Pose2(o.dx_m, o.dy_m, o.dtheta_rad),
                gtsam.noiseModel.Gaussian.Covariance(odometry_noise_covariance(o)),
            ))
        for obs in step.observations:
            noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([obs.sigma_bearing_rad, obs.sigma_range_m]))
            graph.add(gtsam.BearingRangeFactor2D(X(k), L(obs.landmark_id), gtsam.Rot2(obs.bearing_rad), obs.range_m, noise))
    return graph


def test_whole_graph_equals_load2D_factor_by_factor(vp_path, imported, loaded):
    header, records = imported
    theirs, initial = loaded
    pose_ids = chain_pose_ids(vp_path)
    n = len(pose_ids)
    ours = direct_graph(header, records)
    key_map = {pid: X(k) for k, pid in enumerate(pose_ids)}
    their_values = perturbed_values(initial)
    our_values = rekeyed(their_values, pose_ids, n)
    assert_same_factors(theirs, ours, key_map, their_values, our_values)
    # At load2D's own initial values (dead reckoning, landmarks at first sight) the totals
    # agree too; our prior adds nothing there because pose 0 is (0, 0, 0) in both.
    their_error = theirs.error(initial)
    our_error = ours.error(rekeyed(initial, pose_ids, n))
    assert our_error == pytest.approx(their_error, rel=1e-9)


def test_isam2_smoother_graph_equals_load2D_on_a_prefix(vp_path, imported):
    """The project's Isam2Smoother, fed the log's first steps, holds load2D's graph."""
    header, records = imported
    n_steps = 400
    pose_ids = chain_pose_ids(vp_path)
    theirs, initial = gtsam.load2D(vp_path, None, pose_ids[n_steps - 1])  # maxIndex = last file id kept
    smoother = Isam2Smoother(header, update_every=1)  # factors in load2D's order: one step per update
    for step in group_steps(header, records)[:n_steps]:
        smoother.step(step)
    assert smoother.update_failures == 0 and smoother.pending_observations == 0
    ours = smoother.graph()
    assert sum(isinstance(theirs.at(i), gtsam.BearingRangeFactor2D) for i in range(theirs.size())) > 100
    key_map = {pid: X(k) for k, pid in enumerate(pose_ids[:n_steps])}
    their_values = perturbed_values(initial, seed=11)
    assert_same_factors(theirs, ours, key_map, their_values, rekeyed(their_values, pose_ids, n_steps))


# ----------------------------------------------------------------------------- small hand-written files

GOOD = """\
ODOMETRY 0 1 1.0 0.1 0.2 0.0001 0 0 4e-06 0 4e-06
LANDMARK 1 2 3.0 -4.0 0.4 0 0.4

ODOMETRY 1 3 0.5 0.0 -0.3 0.01 0 0.02 0.003 0 0
LANDMARK 3 2 1.0 1.0 0.5 0.1 0.9
LANDMARK 3 4 2.0 0.5 0.2 0 0.2
"""


def test_small_file_both_noise_layouts_and_gtsams_fallback(tmp_path):
    path = tmp_path / "small.txt"
    path.write_text(GOOD)
    header, records = import_victoria_park(path)
    assert [type(r).__name__ for r in records] == ["Odometry", "Observation", "Odometry", "Observation", "Observation"]
    # TORO-ordered line 'v0 0 v2 v3 0 0' = diag(v0, v2, v3)
    np.testing.assert_allclose(rotate_back(records[2].covariance, -0.3), np.diag([0.01, 0.02, 0.003]), atol=1e-17)
    assert records[1].range_m == 5.0 and records[1].bearing_rad == math.atan2(-4.0, 3.0)
    # non-uniform Cartesian covariance: load2D uses sigma 1 and 1
    assert (records[3].sigma_bearing_rad, records[3].sigma_range_m) == (1.0, 1.0)
    assert header.noise["observation"]["lines_with_non_uniform_covariance"] == 1
    assert [s.stamp_s for s in group_steps(header, records)] == pytest.approx([0.0, 0.2, 0.4])

    theirs, initial = gtsam.load2D(str(path))
    ours = direct_graph(header, records)
    their_values = perturbed_values(initial, seed=3)
    pose_ids = [0, 1, 3]
    assert_same_factors(theirs, ours, {0: X(0), 1: X(1), 3: X(2)}, their_values, rekeyed(their_values, pose_ids, 3))


@pytest.mark.parametrize(
    "text, line, words",
    [
        ("ODOMETRY 0 1 1 0 0 0.0001 0 0 4e-06 0 4e-06\nVERTEX2 1 0 0 0\n", 2, "unknown line type"),
        ("ODOMETRY 0 1 1 0 0 0.0001 0 0 4e-06 0\n", 1, "expected 12"),
        ("ODOMETRY 0 1 1 0 zero 0.0001 0 0 4e-06 0 4e-06\n", 1, "dtheta must be a finite decimal number"),
        ("ODOMETRY 0 1 1 0 nan 0.0001 0 0 4e-06 0 4e-06\n", 1, "dtheta"),
        ("ODOMETRY 0 1 1 0 0 0.0001 0 0 4e-06 0 4e-06\nODOMETRY 0 2 1 0 0 0.0001 0 0 4e-06 0 4e-06\n", 2,
         "does not start at the latest pose 1"),
        ("ODOMETRY 0 1 1 0 0 0.0001 0 0 4e-06 0 4e-06\nODOMETRY 1 0 1 0 0 0.0001 0 0 4e-06 0 4e-06\n", 2,
         "loop-closure"),
        ("ODOMETRY 0 1 1 0 0 0.0001 0.5 0 4e-06 0 4e-06\n", 1, "match neither layout"),
        ("ODOMETRY 0 1 1 0 0 -0.0001 0 0 4e-06 0 4e-06\n", 1, "must be > 0"),
        ("ODOMETRY -1 1 1 0 0 0.0001 0 0 4e-06 0 4e-06\n", 1, "non-negative integer"),
        ("ODOMETRY 0 1 1 0 0 0.0001 0 0 4e-06 0 4e-06\nODOMETRY 1 2 1 0 0 0.0001 0 0 4e-06 0 4e-06\n"
         "LANDMARK 1 9 3 4 0.4 0 0.4\n", 3, "latest pose is 2"),
        ("ODOMETRY 0 1 1 0 0 0.0001 0 0 4e-06 0 4e-06\nLANDMARK 1 9 0 0 0.4 0 0.4\n", 2, "zero range"),
        ("ODOMETRY 0 1 1 0 0 0.0001 0 0 4e-06 0 4e-06\nLANDMARK 1 9 3 4 0 0 0\n", 2, "must be > 0"),
        ("ODOMETRY 0 1 1 0 0 0.0001 0 0 4e-06 0 4e-06\nLANDMARK 1 9 3 4 0.4 0 0.4 7\n", 2, "expected 8"),
        ("\n\n", 2, "no ODOMETRY or LANDMARK lines"),
    ],
)
def test_bad_lines_name_file_and_line(tmp_path, text, line, words):
    path = tmp_path / "bad.txt"
    path.write_text(text)
    with pytest.raises(DatasetFormatError) as info:
        import_victoria_park(path)
    message = str(info.value)
    assert message.startswith(f"{path}:{line}: "), message
    assert words in message, message
    assert info.value.line == line and isinstance(info.value, FgslamError)


def test_binary_garbage_and_missing_file(tmp_path):
    path = tmp_path / "bin.txt"
    path.write_bytes(b"ODOMETRY 0 1 1 0 0 0.0001 0 0 4e-06 0 4e-06\n\xff\xfe\x00\n")
    with pytest.raises(DatasetFormatError, match=r"bin\.txt:2: not plain ASCII"):
        import_victoria_park(path)
    with pytest.raises(FgslamError, match="cannot open"):
        import_victoria_park(tmp_path / "missing.txt")

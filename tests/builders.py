"""Small record builders and helpers shared by the tests (pytest puts tests/ on the import path)."""

from __future__ import annotations

import json
import time

from slamio.log import Header, read_log, write_log
from slamio.sim3d import DriveScenario

#: The short drive of :func:`write_small_drive`.
SMALL_DRIVE = DriveScenario(straight_m=40.0, side_m=25.0)


def wait_for(predicate, timeout_s=30.0):
    """Poll ``predicate`` until it is true or ``timeout_s`` of wall time has passed; its last value.

    For tests that wait on an event (a stop command, a record) instead of sleeping: the
    timeout only bounds a hang, it never decides a pass on a busy machine."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.002)
    return predicate()


def minimal_header(start_pose=(0.0, 0.0, 0.0), start_sigma=(1e-3, 1e-3, 1e-3), stamp_s=0.0) -> Header:
    """A valid header with placeholder robot/sensor/noise descriptions."""
    return Header(
        stamp_s=float(stamp_s),
        start_pose=tuple(float(v) for v in start_pose),
        start_sigma=tuple(float(v) for v in start_sigma),
        robot={"name": "test"},
        sensor={"kind": "test"},
        noise={"odometry": {}, "observation": {}},
    )


def run_estimator(estimator, steps):
    """``estimator`` (anything with ``step`` and ``finish``) fed every step, then finished."""
    for step in steps:
        estimator.step(step)
    estimator.finish()
    return estimator


def run_smoother(header: Header, steps, **kwargs):
    """An ``Isam2Smoother(header, **kwargs)`` fed every step, then finished."""
    from fgslam.smoother import Isam2Smoother

    return run_estimator(Isam2Smoother(header, **kwargs), steps)


def assert_arena_run_is_sane(estimator, steps, n_landmarks=8):
    """The finished ``estimator`` on a simulated arena log: one finite pose a step, a finite
    covariance, every arena landmark mapped, one association per observation of the last step."""
    import numpy as np

    t = estimator.trajectory()
    assert t.shape == (len(steps), 3)
    assert np.isfinite(t).all()
    assert np.isfinite(estimator.current_covariance()).all()
    assert set(estimator.landmarks()) == set(range(n_landmarks))
    assert len(estimator.step_associations()) == len(steps[-1].observations)


def assert_log_round_trips(path, header, records):
    """``header`` and ``records`` written to ``path`` read back exactly, untruncated; the read log."""
    write_log(path, header, records)
    log = read_log(path)
    assert log.truncated is None
    assert log.header == header
    assert log.records == tuple(records)
    return log


def run_main_with_json(main, args, out, capsys):
    """``main([*args, "--json", out])`` succeeds; what it printed and the JSON it wrote."""
    assert main([*args, "--json", str(out)]) == 0
    return capsys.readouterr().out, json.loads(out.read_text())


def sim_steps(sim, seconds: float) -> None:
    """Step a hand-stepped simulated Create through ``seconds`` of robot time."""
    from slamio.create.sim import STEP_S

    for _ in range(round(seconds / STEP_S)):
        sim.step()


def retained_bytes(read, path) -> int:
    """What the result of ``read(path)`` holds in memory (tracemalloc), bytes."""
    import gc
    import tracemalloc

    gc.collect()
    tracemalloc.start()
    try:
        kept = read(path)
        size, _ = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    del kept
    return size


def write_small_drive(path):
    """A short simulated stereo + IMU drive (seed 5, 40 m × 25 m) written as a 3-D log at
    ``path``; returns ``path``."""
    from slamio.datasets.seed003_log import drive_to_log
    from slamio.sim3d import simulate_drive

    header, records = drive_to_log(simulate_drive(5, SMALL_DRIVE), source={"generator": "test"})
    write_log(path, header, records)
    return path

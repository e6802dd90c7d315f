"""Small record builders and helpers shared by the tests (pytest puts tests/ on the import path)."""

from __future__ import annotations

import time

from slamio.log import Header


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


def run_smoother(header: Header, steps, **kwargs):
    """An ``Isam2Smoother(header, **kwargs)`` fed every step, then finished."""
    from fgslam.smoother import Isam2Smoother

    smoother = Isam2Smoother(header, **kwargs)
    for step in steps:
        smoother.step(step)
    smoother.finish()
    return smoother

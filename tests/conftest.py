"""What every test module shares: no test may depend on how fast this machine is.

* **Hypothesis** runs without its per-example deadline (200 ms by default) and without its
  "too slow" health check: on a busy machine an example can take longer than that, which
  says nothing about the code (profile ``fgslam``; ``--hypothesis-profile`` picks another).
  It is derandomised, like every other draw in the tests; ``fgslam-explore`` hunts.
* **The ``slow`` marker** (registered in pyproject.toml) is put on the long acceptance runs
  listed in :data:`SLOW`. ``make test`` (``pytest -n auto -m "not slow"``) leaves them out and
  finishes in a few minutes; ``make test-all`` (``pytest -n auto``) and CI run everything,
  one process per core (pytest-xdist): no test may rely on running alone, in order or in
  the same process as another.
  A test can also say it is slow itself with ``@pytest.mark.slow``.
* **``cable_back_on_retry``**: a pulled serial cable that goes back in right after the
  link's first attempt to reopen it — "back within the retry window" as an event, not as a
  delay that a busy machine could overrun.
"""

from __future__ import annotations

import warnings

import pytest
from hypothesis import HealthCheck, settings

# Derandomised: every run draws the same examples, so a test that passed passes again (the
# project seeds all its randomness). To hunt for new failures, run with
# `--hypothesis-profile fgslam-explore` (fresh random examples, more of them) and keep each
# failure it finds as an explicit test case.
settings.register_profile("fgslam", deadline=None, suppress_health_check=[HealthCheck.too_slow], derandomize=True)
settings.register_profile("fgslam-explore", deadline=None, suppress_health_check=[HealthCheck.too_slow],
                          max_examples=2000)
settings.load_profile("fgslam")

# (module file, test name with its parameters): the long acceptance runs, up to minutes
# each on a busy 2-core machine (`pytest --durations=40` finds them).
SLOW = {
    ("test_acceptance.py", "test_grid_200_skeleton_promises"),
    ("test_acceptance.py", "test_jcbb_associates_hidden_ids_at_least_99_percent_and_nn_no_better[grid-200]"),
    ("test_acceptance.py", "test_dcs_isam2_with_10_percent_outliers_on_grid_200_stays_within_1_2x_of_clean"),
    ("test_cli.py", "test_victoria_park_with_the_fast_preset_ends_at_the_smoothed_reference"),  # 6 969 real poses
    ("test_plaza.py", "test_import_then_run_reports_ate_against_gps"),
    # the front-end's error table against the bounds (one rendered table, 4 tests)
    ("test_camera_accuracy.py", "test_every_landmark_is_measured"),
    ("test_camera_accuracy.py", "test_tag_range_and_bearing_errors"),
    ("test_camera_accuracy.py", "test_cylinder_range_bearing_and_height_errors"),
    ("test_camera_accuracy.py", "test_seed_formulas_show_their_documented_errors"),
}


@pytest.hookimpl(tryfirst=True)  # before -m deselects by marker
def pytest_collection_modifyitems(config, items):
    modules = {}
    for item in items:
        if (item.path.name, item.name) in SLOW:
            item.add_marker(pytest.mark.slow)
        modules.setdefault(item.path.name, getattr(item, "module", None))
    for file, name in sorted(SLOW):  # a renamed test would silently join the quick run
        module = modules.get(file)
        if module is not None and not hasattr(module, name.split("[", 1)[0]):
            warnings.warn(pytest.PytestWarning(f"tests/conftest.py: SLOW names {file}::{name}, which does not exist"))


@pytest.fixture
def cable_back_on_retry():
    """``make(sim) -> (opener, attempts)``: give ``opener`` to :class:`CreateLink`. While
    ``sim`` is unplugged, the link's first attempt to open the port fails (the cable is out)
    and plugs the cable back in, so the next attempt succeeds; ``attempts`` lists the
    attempts made while unplugged."""
    import serial

    def make(sim):
        attempts: list[str] = []

        def opener(url, **kwargs):
            if not sim.plugged:
                attempts.append(url)
                try:
                    return serial.serial_for_url(url, **kwargs)  # fails: no port behind the path
                finally:
                    sim.replug()
            return serial.serial_for_url(url, **kwargs)

        return opener, attempts

    return make


@pytest.fixture
def manual():
    """``make(model="create2", **kwargs) -> (sim, port)``: simulated Creates stepped by hand
    (no pacing thread), each with a pyserial port on its pseudo-terminal; closed after the test."""
    import serial

    from slamio.create.sim import SimulatedCreate

    made = []

    def make(model="create2", **kwargs):
        sim = SimulatedCreate(model, **kwargs).start(thread=False)
        port = serial.serial_for_url(sim.port, baudrate=115200, timeout=0.5)
        made.append((sim, port))
        return sim, port

    yield make
    for sim, port in made:
        port.close()
        sim.close()

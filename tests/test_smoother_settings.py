"""Isam2Settings: the smoother's knobs, validated once, turned into GTSAM's ISAM2Params.

The reference for the parameters is GTSAM's own printout of the ``ISAM2Params`` object
(``str(params)``), not our code's reading of it.
"""

from __future__ import annotations

import dataclasses

import pytest

from fgslam.smoother import FAST_SETTINGS, Isam2Settings, Isam2Smoother
from slamio.errors import FgslamError
from slamio.sim import simulate


def _printed(params) -> dict[str, str]:
    """GTSAM's printout of an ISAM2Params as {field: value}."""
    out = {}
    for line in str(params).splitlines():
        key, _, value = line.partition(":")
        if value.strip():
            out[key.strip()] = value.strip()
    return out


def test_the_defaults_reach_gtsam():
    printed = _printed(Isam2Settings().isam2_params())
    assert printed["relinearizeThreshold"] == "0.01"
    assert printed["relinearizeSkip"] == "20"
    assert printed["factorization"] == "CHOLESKY"
    assert printed["wildfireThreshold"] == "1"
    assert printed["cacheLinearizedFactors"] == "1"
    assert printed["enablePartialRelinearizationCheck"] == "0"


def test_knobs_reach_gtsam_and_are_normalised():
    settings = Isam2Settings(relinearize_skip=3, factorization="QR", wildfire_threshold=0.001,
                             relinearize_threshold=[1, 0.05], update_every=7.0)
    assert settings.relinearize_threshold == (1.0, 0.05)  # a list becomes a (metres, radians) pair
    assert settings.factorization == "qr"
    assert settings.update_every == 7 and isinstance(settings.update_every, int)
    printed = _printed(settings.isam2_params())
    assert printed["relinearizeSkip"] == "3"
    assert printed["factorization"] == "QR"
    assert printed["wildfireThreshold"] == "0.001"


def test_settings_are_frozen_and_unknown_knobs_refused():
    settings = Isam2Settings()
    with pytest.raises(dataclasses.FrozenInstanceError):
        settings.update_every = 1  # type: ignore[misc]
    with pytest.raises(TypeError, match="update_evry"):
        Isam2Settings(update_evry=1)


@pytest.mark.parametrize("knobs, names", [
    ({"relinearize_skip": 0}, "relinearize_skip"),
    ({"final_updates": -1}, "final_updates"),
    ({"max_retries": -1}, "max_retries"),
    ({"update_every": 0}, "update_every"),
    ({"max_held_steps": 0}, "max_held_steps"),
    ({"final_iterations": -1}, "final_iterations"),
    ({"final_tolerance": float("nan")}, "final_tolerance"),
    ({"update_on": "sometimes"}, "update_on"),
    ({"factorization": "lu"}, "factorization"),
    ({"wildfire_threshold": -1.0}, "wildfire_threshold"),
    ({"max_keyframe_gap": 0}, "max_keyframe_gap"),
    ({"relinearize_max_variables": -1}, "relinearize_max_variables"),
    ({"relinearize_threshold": (1.0,)}, "relinearize_threshold"),
    ({"relinearize_threshold": float("inf")}, "relinearize_threshold"),
])
def test_bad_knobs_are_named(knobs, names):
    with pytest.raises(FgslamError, match=names):
        Isam2Settings(**knobs)


def test_the_smoother_keeps_its_settings_and_the_fast_preset_builds():
    header, _ = simulate("arena-octagon", 1)
    smoother = Isam2Smoother(header, update_every=1, robust="dcs")
    assert smoother.settings == Isam2Settings(update_every=1)
    assert smoother.name == "isam2-dcs"
    fast = Isam2Smoother(header, **FAST_SETTINGS)
    assert fast.settings == Isam2Settings(**FAST_SETTINGS)
    assert fast.settings.keyframes is True
    with pytest.raises(FgslamError, match="update_every"):
        Isam2Smoother(header, update_every=0)

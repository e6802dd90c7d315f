"""The one registry of estimators (fgslam.registry): names, dimensions, errors."""

from __future__ import annotations

import pytest

from fgslam.registry import DEFAULTS, REGISTRY, build, entry, help_for, isam2_names, names_for, parse_names
from slamio.errors import FgslamError


def test_every_name_takes_one_dimension_and_has_help():
    assert set(REGISTRY) == set(names_for(2)) | set(names_for(3))
    assert not set(names_for(2)) & set(names_for(3))
    for e in REGISTRY.values():
        assert e.dimension in (2, 3) and e.help and callable(e.factory)
    for dimension, names in DEFAULTS.items():
        assert all(REGISTRY[n].dimension == dimension for n in names)
    assert isam2_names(3) == ("isam2-3d",)
    assert "isam2" in isam2_names(2) and "ekf" not in isam2_names(2)


def test_the_runners_and_the_help_read_the_registry():
    from fgslam.cli.estimators import ESTIMATOR_HELP, ESTIMATOR_HELP_3D
    from fgslam.runner import ESTIMATORS
    from fgslam.runner3d import ESTIMATORS_3D

    assert list(ESTIMATORS) == list(ESTIMATOR_HELP) == names_for(2)
    assert list(ESTIMATORS_3D) == list(ESTIMATOR_HELP_3D) == names_for(3)
    assert help_for(3)["isam2-3d"].startswith("GTSAM iSAM2 on Pose3")


def test_a_wrong_dimension_name_lists_the_valid_ones_for_that_log():
    with pytest.raises(FgslamError) as error:
        parse_names("ekf-vio,isam2", 2)
    text = str(error.value)
    assert text.startswith("unknown estimator(s) ekf-vio; choose from ekf, ekf-nn")
    assert "ekf-vio takes a 3-D log, this is a planar log" in text
    with pytest.raises(FgslamError, match=r"unknown estimator\(s\) for a 3-D log: ekf; choose from ekf-s003, "):
        entry("ekf", 3)
    with pytest.raises(FgslamError, match="keep isam2-3d"):
        parse_names("ekf-vio", 3)
    assert parse_names(None, 3) == list(DEFAULTS[3])
    assert parse_names("ekf, ekf", 2, need_isam2=False) == ["ekf"]


def test_build_names_a_3d_estimator_by_its_registry_name():
    from slamio.sim3d import DriveScenario, simulate_drive
    from slamio.datasets.seed003 import StereoImuNoise
    from slamio.log import StereoCalibration

    drive = simulate_drive(0, DriveScenario())
    rig = StereoCalibration(drive.K, drive.baseline_m, drive.cam_T_imu)
    assert build("ekf-s003-figures", 3, rig, StereoImuNoise()).name == "ekf-s003-figures"

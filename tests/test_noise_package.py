"""slamio.noise: one home for noise, one error class, imports that point one way."""

from __future__ import annotations

import importlib.util
import subprocess
import sys

import pytest

from slamio.errors import FgslamError, InputFileError
from slamio.noise.errors import NoiseModelError, NoiseModelFileError

OLD_MODULES = ("slamio.noise_model", "slamio.noise_fit", "slamio.noise_apply", "slamio.range_fit",
               "slamio.create.calibrate")


@pytest.mark.parametrize("name", OLD_MODULES)
def test_the_old_homes_are_gone(name):
    assert importlib.util.find_spec(name) is None


def test_one_error_class_and_its_file_variant():
    assert issubclass(NoiseModelError, FgslamError) and not issubclass(NoiseModelError, InputFileError)
    assert issubclass(NoiseModelFileError, NoiseModelError) and issubclass(NoiseModelFileError, InputFileError)


def _loaded_after(module: str) -> set[str]:
    code = f"import sys, {module}; print(' '.join(m for m in sys.modules if m.startswith('slamio.noise')))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    return set(out.split())


def test_applying_a_model_does_not_load_any_fit():
    loaded = _loaded_after("slamio.noise.apply")
    assert not loaded & {"slamio.noise.fit_truth", "slamio.noise.fitting", "slamio.noise.range"}


def test_the_range_fit_does_not_import_the_truth_fit():
    """No circle: the range fit and the truth fit share slamio.noise.fitting, not each other."""
    assert "slamio.noise.fit_truth" not in _loaded_after("slamio.noise.range")

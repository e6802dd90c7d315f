"""slamio.noise.model: the noise-model file (round trip, validation), and
slamio.noise.apply.correct_observation.

The forward model of a reading is written out here independently of the module (the
docstring's formulas): ``measured_bearing = bearing_scale·b + bearing_bias_rad`` and
``measured_range = range_scale·(r·cos b if range_is_depth else r) + range_bias_m``;
correct_observation must invert it exactly.
"""

from __future__ import annotations

import json
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from slamio.errors import FgslamError
from slamio.noise.apply import correct_observation
from slamio.noise.errors import NoiseModelError
from slamio.noise.model import (
    NOISE_MODEL_FORMAT,
    NoiseModel,
    ObservationModel,
    OdometryModel,
    OdometryNoiseRates,
    load_noise_model,
    noise_model_from_dict,
    save_noise_model,
)

#: Every field away from its default, so a field dropped on the way out or in shows up.
MODEL = NoiseModel(
    odometry=OdometryModel(
        lag_s=0.21,
        forward_scale=0.93,
        turn_scale=0.951,
        turn_per_m_rad=-0.04,
        noise=OdometryNoiseRates(
            forward_m2_per_m=1.5e-4, lateral_m2_per_m=2.5e-5, heading_rad2_per_rad=3e-4,
            heading_rad2_per_m=1e-5, forward_m2_per_s=2e-6, lateral_m2_per_s=3e-6, heading_rad2_per_s=4e-6,
        ),
    ),
    observation=ObservationModel(
        range_is_depth=True, range_scale=1.03, range_bias_m=0.02, range_sigma_m=0.004,
        range_sigma_per_m=0.01, bearing_scale=0.99, bearing_bias_rad=-0.002, bearing_sigma_rad=0.006,
        bearing_sigma_s=0.01, camera_latency_s=0.03, outlier_rate=0.012,
    ),
    fitted_on=("runs/robot1.jsonl", "runs/robot2.jsonl"),
    fit_report={"odometry": {"windows": 262, "residual_mad": [0.0002, 0.0003, 0.0018]},
                "observation": {"observations": 2175, "outliers": 20}},
)


def valid_dict() -> dict:
    """A fresh, valid file body (JSON types only) to break one field of."""
    return json.loads(json.dumps(MODEL.to_dict()))


def write_json_text(path, text: str) -> str:
    path.write_text(text, encoding="utf-8")
    return str(path)


def write_valid_with(tmp_path, **fields) -> str:
    """A valid file body with the top-level ``fields`` set, written to ``noise.json``; its path."""
    return write_json_text(tmp_path / "noise.json", json.dumps({**valid_dict(), **fields}))


# ----------------------------------------------------------------------------- the file


def test_save_then_load_gives_an_equal_model(tmp_path):
    path = tmp_path / "noise.json"
    save_noise_model(path, MODEL)
    loaded = load_noise_model(path)
    assert loaded == MODEL
    assert isinstance(loaded.fitted_on, tuple)
    body = json.loads(path.read_text())
    assert body["format"] == NOISE_MODEL_FORMAT and body["version"] == 1
    assert body["observation"]["range_is_depth"] is True


def test_the_default_model_round_trips(tmp_path):
    path = tmp_path / "default.json"
    save_noise_model(str(path), NoiseModel())
    assert load_noise_model(str(path)) == NoiseModel()


def test_missing_sections_take_the_defaults():
    model = noise_model_from_dict({"format": NOISE_MODEL_FORMAT, "version": 1})
    assert model == NoiseModel()


def test_save_refuses_to_overwrite_an_existing_file(tmp_path):
    path = tmp_path / "noise.json"
    path.write_text("precious\n")
    with pytest.raises(NoiseModelError, match="exists") as info:
        save_noise_model(path, MODEL)
    assert str(path) in str(info.value)
    assert path.read_text() == "precious\n"  # untouched
    save_noise_model(path, MODEL, overwrite=True)
    assert load_noise_model(path) == MODEL


def test_save_into_a_missing_folder_is_a_noise_model_error(tmp_path):
    with pytest.raises(NoiseModelError, match="cannot write"):
        save_noise_model(tmp_path / "no" / "such" / "noise.json", MODEL)


def test_noise_model_error_is_an_fgslam_error():
    assert issubclass(NoiseModelError, FgslamError)


# ----------------------------------------------------------------------------- validation

#: (section path, field, bad value, words the message must contain)
BAD_FIELDS = [
    (("observation",), "range_sigma_m", -0.1, "observation.range_sigma_m"),
    (("observation",), "range_sigma_m", 0.0, "observation.range_sigma_m"),
    (("observation",), "bearing_sigma_rad", -1e-3, "observation.bearing_sigma_rad"),
    (("observation",), "range_sigma_per_m", -0.01, "observation.range_sigma_per_m"),
    (("observation",), "bearing_sigma_s", -0.01, "observation.bearing_sigma_s"),
    (("observation",), "range_scale", 0.0, "observation.range_scale"),
    (("observation",), "bearing_scale", -1.0, "observation.bearing_scale"),
    (("observation",), "outlier_rate", -0.1, "observation.outlier_rate"),
    (("observation",), "outlier_rate", 1.0, "observation.outlier_rate"),
    (("observation",), "camera_latency_s", 6.0, "observation.camera_latency_s"),
    (("observation",), "correlated_share", 1.0, "observation.correlated_share"),
    (("observation",), "correlated_share", -0.1, "observation.correlated_share"),
    (("observation",), "correlation_time_s", -1.0, "observation.correlation_time_s"),
    (("observation",), "range_bias_m", "0.02", "observation.range_bias_m"),
    (("observation",), "range_scale", True, "observation.range_scale"),
    (("observation",), "range_scale", None, "observation.range_scale"),
    (("observation",), "range_is_depth", "yes", "observation.range_is_depth"),
    (("observation",), "range_is_depth", 1, "observation.range_is_depth"),
    (("odometry",), "lag_s", 7.5, "odometry.lag_s"),
    (("odometry",), "forward_scale", 0.0, "odometry.forward_scale"),
    (("odometry",), "turn_scale", -0.9, "odometry.turn_scale"),
    (("odometry",), "turn_per_m_rad", [0.1], "odometry.turn_per_m_rad"),
    (("odometry", "noise"), "forward_m2_per_m", -1e-4, "odometry.noise.forward_m2_per_m"),
    (("odometry", "noise"), "heading_rad2_per_rad", -1e-4, "odometry.noise.heading_rad2_per_rad"),
    (("odometry", "noise"), "heading_rad2_per_s", 0.0, "odometry.noise.heading_rad2_per_s"),
    (("odometry", "noise"), "lateral_m2_per_s", 0.0, "odometry.noise.lateral_m2_per_s"),
]


@pytest.mark.parametrize("section, name, value, words", BAD_FIELDS)
def test_a_bad_field_is_named(tmp_path, section, name, value, words):
    data = valid_dict()
    target = data
    for key in section:
        target = target[key]
    target[name] = value
    path = write_json_text(tmp_path / "noise.json", json.dumps(data))
    with pytest.raises(NoiseModelError) as info:
        load_noise_model(path)
    message = str(info.value)
    assert words in message
    assert message.startswith(path)  # and the file
    assert "\n" not in message


def test_correlated_readings_need_a_correlation_time():
    with pytest.raises(NoiseModelError, match=r"observation\.correlation_time_s must be > 0"):
        ObservationModel(correlated_share=0.5)
    assert ObservationModel(correlated_share=0.5, correlation_time_s=10.0).correlated_share == 0.5


@pytest.mark.parametrize("section, name, value, words", BAD_FIELDS)
def test_the_dataclasses_check_their_own_fields(section, name, value, words):
    cls = {("observation",): ObservationModel, ("odometry",): OdometryModel,
           ("odometry", "noise"): OdometryNoiseRates}[section]
    with pytest.raises(NoiseModelError, match=words.replace(".", r"\.")):
        cls(**{name: value})


@pytest.mark.parametrize("literal", ["NaN", "Infinity", "-Infinity"])
@pytest.mark.parametrize("section, name", [("observation", "bearing_sigma_rad"), ("observation", "range_bias_m"),
                                           ("odometry", "lag_s")])
def test_non_finite_numbers_are_refused(tmp_path, literal, section, name):
    # Python's json reads the NaN / Infinity literals: the reader refuses them, naming the line and field
    data = valid_dict()
    data[section][name] = "__HERE__"
    text = json.dumps(data, indent=2).replace('"__HERE__"', literal)
    path = write_json_text(tmp_path / "noise.json", text)
    line = text[: text.index(literal)].count("\n") + 1
    with pytest.raises(NoiseModelError, match=rf"noise\.json:{line}: field '{section}\.{name}' is not a number"):
        load_noise_model(path)


@pytest.mark.parametrize("section", [("observation",), ("odometry",), ("odometry", "noise")])
def test_an_unknown_field_is_named(tmp_path, section):
    data = valid_dict()
    target = data
    for key in section:
        target = target[key]
    target["sigma_rnage_m"] = 0.1
    path = write_json_text(tmp_path / "noise.json", json.dumps(data))
    with pytest.raises(NoiseModelError) as info:
        load_noise_model(path)
    message = str(info.value)
    assert "unknown field" in message and "sigma_rnage_m" in message
    assert ".".join(section) in message
    assert message.startswith(path)


def test_an_unknown_top_level_field_is_named(tmp_path):
    data = valid_dict()
    data["observaton"] = data.pop("observation")
    path = write_json_text(tmp_path / "noise.json", json.dumps(data))
    with pytest.raises(NoiseModelError, match="observaton"):
        load_noise_model(path)


@pytest.mark.parametrize("section, value", [("observation", []), ("odometry", 3), ("odometry.noise", "x")])
def test_a_section_that_is_not_an_object_is_named(tmp_path, section, value):
    data = valid_dict()
    if section == "odometry.noise":
        data["odometry"]["noise"] = value
    else:
        data[section] = value
    path = write_json_text(tmp_path / "noise.json", json.dumps(data))
    with pytest.raises(NoiseModelError, match=rf"{section} must be a JSON object"):
        load_noise_model(path)


@pytest.mark.parametrize("fmt", ["fgslam-log", None, 1, "FGSLAM-NOISE-MODEL"])
def test_a_wrong_format_is_refused(tmp_path, fmt):
    data = valid_dict()
    if fmt is None:
        del data["format"]
    else:
        data["format"] = fmt
    path = write_json_text(tmp_path / "noise.json", json.dumps(data))
    with pytest.raises(NoiseModelError, match='not an fgslam noise model.*"format"') as info:
        load_noise_model(path)
    assert "fgslam calibrate" in str(info.value)


@pytest.mark.parametrize("body", ["[1, 2]", '"fgslam-noise-model"', "null", "3"])
def test_json_that_is_not_an_object_is_refused(tmp_path, body):
    path = write_json_text(tmp_path / "noise.json", body)
    with pytest.raises(NoiseModelError, match="not an fgslam noise model"):
        load_noise_model(path)


@pytest.mark.parametrize("version", [0, 2, "1", None])
def test_a_wrong_version_is_refused(tmp_path, version):
    path = write_valid_with(tmp_path, version=version)
    with pytest.raises(NoiseModelError, match="version"):
        load_noise_model(path)


@pytest.mark.parametrize("fitted_on", ["run.jsonl", [1, 2], {"a": 1}])
def test_fitted_on_must_be_a_list_of_strings(tmp_path, fitted_on):
    path = write_valid_with(tmp_path, fitted_on=fitted_on)
    with pytest.raises(NoiseModelError, match="fitted_on"):
        load_noise_model(path)


def test_fit_report_must_be_an_object(tmp_path):
    path = write_valid_with(tmp_path, fit_report=[1])
    with pytest.raises(NoiseModelError, match="fit_report"):
        load_noise_model(path)


def test_bad_json_names_the_line(tmp_path):
    text = '{\n  "format": "fgslam-noise-model",\n  "version": 1,\n  "odometry": {"lag_s": 0.2,}\n}\n'
    path = write_json_text(tmp_path / "noise.json", text)
    with pytest.raises(NoiseModelError) as info:
        load_noise_model(path)
    message = str(info.value)
    assert message.startswith(f"{path}:4: not valid JSON")
    assert "column" in message


def test_an_empty_file_is_bad_json_on_line_1(tmp_path):
    path = write_json_text(tmp_path / "noise.json", "")
    with pytest.raises(NoiseModelError, match=r":1: not valid JSON"):
        load_noise_model(path)


def test_deeply_nested_json_is_one_clear_error(tmp_path):
    path = write_json_text(tmp_path / "noise.json", "[" * 200_000 + "]" * 200_000)
    with pytest.raises(NoiseModelError, match="noise.json:1: field .* is nested more than 64 levels deep"):
        load_noise_model(path)


def test_a_missing_file_is_named(tmp_path):
    path = str(tmp_path / "nope.json")
    with pytest.raises(NoiseModelError, match="no such noise-model file") as info:
        load_noise_model(path)
    assert str(info.value).startswith(path)
    assert "fgslam calibrate" in str(info.value)


def test_a_file_that_is_not_text_is_refused(tmp_path):
    path = tmp_path / "noise.json"
    path.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(NoiseModelError, match="noise.json:1: not UTF-8"):
        load_noise_model(path)


def test_a_folder_is_not_a_noise_model(tmp_path):
    with pytest.raises(NoiseModelError, match="is a folder, not a regular file"):
        load_noise_model(tmp_path)


# ----------------------------------------------------------------------------- correct_observation


def forward(model: ObservationModel, r: float, b: float) -> tuple[float, float]:
    """The reading a camera described by ``model`` reports for true range r and bearing b."""
    along = r * math.cos(b) if model.range_is_depth else r
    return model.range_scale * along + model.range_bias_m, model.bearing_scale * b + model.bearing_bias_rad


@settings(max_examples=300, derandomize=True, deadline=None)
@given(
    range_scale=st.floats(0.8, 1.25),
    range_bias=st.floats(-0.1, 0.1),
    bearing_scale=st.floats(0.8, 1.25),
    bearing_bias=st.floats(-0.05, 0.05),
    depth=st.booleans(),
    r=st.floats(0.3, 8.0, exclude_min=True, exclude_max=True),
    b=st.floats(-1.0, 1.0, exclude_min=True, exclude_max=True),
    turn_rate=st.floats(0.0, 2.0),
)
def test_correct_observation_inverts_the_forward_model(range_scale, range_bias, bearing_scale, bearing_bias,
                                                       depth, r, b, turn_rate):
    model = ObservationModel(range_is_depth=depth, range_scale=range_scale, range_bias_m=range_bias,
                             bearing_scale=bearing_scale, bearing_bias_rad=bearing_bias,
                             range_sigma_m=0.01, range_sigma_per_m=0.01, bearing_sigma_rad=0.005,
                             bearing_sigma_s=0.01)
    measured_r, measured_b = forward(model, r, b)
    r_c, b_c, sigma_r, sigma_b = correct_observation(model, measured_r, measured_b, turn_rate)
    assert r_c == pytest.approx(r, abs=1e-9, rel=0)
    assert b_c == pytest.approx(b, abs=1e-9, rel=0)
    assert math.isfinite(sigma_r) and sigma_r > 0.0
    # the model's σ are of the raw reading: the correction divides them by the scale
    assert sigma_b == pytest.approx(math.hypot(0.005, 0.01 * turn_rate) / bearing_scale, rel=1e-12)


def test_the_identity_model_passes_readings_through():
    r, b, sr, sb = correct_observation(ObservationModel(), 2.5, -0.3, 0.7)
    assert (r, b, sr, sb) == (2.5, -0.3, 0.1, 0.05)


def test_sigma_formulas_by_hand():
    # 3-4-5: sqrt(0.03² + (0.02·2)²) = 0.05 and sqrt(0.006² + (0.016·0.5)²) = 0.01
    model = ObservationModel(range_sigma_m=0.03, range_sigma_per_m=0.02, bearing_sigma_rad=0.006, bearing_sigma_s=0.016)
    assert model.sigma_range_m(2.0) == pytest.approx(0.05, rel=1e-12)
    assert model.sigma_range_m(0.0) == pytest.approx(0.03, rel=1e-12)
    assert model.sigma_bearing_rad(0.5) == pytest.approx(0.01, rel=1e-12)
    assert model.sigma_bearing_rad(-0.5) == pytest.approx(0.01, rel=1e-12)  # |ω|
    assert model.sigma_bearing_rad(0.0) == pytest.approx(0.006, rel=1e-12)
    # Euclidean range: the range's own σ, the bearing's σ at the turn rate
    r, b, sr, sb = correct_observation(model, 2.0, 0.1, 0.5)
    assert (r, b) == (2.0, 0.1)
    assert sr == pytest.approx(0.05, rel=1e-12) and sb == pytest.approx(0.01, rel=1e-12)


def test_depth_sigma_by_hand():
    # depth 1.0 at bearing 60°: r = 1/cos 60° = 2, σ_depth(2) = 0.05, stretched by 1/cos = 0.1,
    # plus r·tan b·σ_b = 2·√3·0.01 = 0.034641: √(0.01 + 0.0012) = √0.0112 = 0.1058301
    model = ObservationModel(range_is_depth=True, range_sigma_m=0.03, range_sigma_per_m=0.02,
                             bearing_sigma_rad=0.006, bearing_sigma_s=0.016)
    r, b, sr, sb = correct_observation(model, 1.0, math.pi / 3, 0.5)
    assert r == pytest.approx(2.0, rel=1e-12) and b == pytest.approx(math.pi / 3, rel=1e-12)
    assert sr == pytest.approx(math.sqrt(0.0112), rel=1e-9)
    assert sb == pytest.approx(0.01, rel=1e-12)
    # straight ahead the depth is the range, and so are the σ
    r, b, sr, _ = correct_observation(model, 2.0, 0.0, 0.5)
    assert (r, b) == (2.0, 0.0) and sr == pytest.approx(0.05, rel=1e-12)


def test_a_depth_reading_far_aside_cannot_be_corrected():
    model = ObservationModel(range_is_depth=True)
    correct_observation(model, 1.0, math.radians(79.0), 0.0)  # still fine
    with pytest.raises(NoiseModelError, match="depth reading"):
        correct_observation(model, 1.0, math.radians(81.0), 0.0)
    with pytest.raises(NoiseModelError, match="depth reading"):
        correct_observation(model, 1.0, -math.radians(100.0), 0.0)


@pytest.mark.parametrize("depth", [False, True])
def test_a_reading_that_corrects_to_a_non_positive_range_is_refused(depth):
    model = ObservationModel(range_is_depth=depth, range_bias_m=0.5)
    with pytest.raises(NoiseModelError, match="non-positive range"):
        correct_observation(model, 0.4, 0.0, 0.0)
    with pytest.raises(NoiseModelError, match="non-positive range"):
        correct_observation(model, 0.5, 0.0, 0.0)


def test_odometry_stretch_covariance_by_hand():
    rates = OdometryNoiseRates(forward_m2_per_m=0.01, lateral_m2_per_m=0.002, heading_rad2_per_rad=0.03,
                               heading_rad2_per_m=0.004, forward_m2_per_s=1e-5, lateral_m2_per_s=2e-5,
                               heading_rad2_per_s=3e-5)
    P = rates.stretch_covariance(-0.5, -0.2, 2.0)  # |Δs| and |Δθ|
    assert P.shape == (3, 3)
    assert P[0, 0] == pytest.approx(0.01 * 0.5 + 1e-5 * 2)
    assert P[1, 1] == pytest.approx(0.002 * 0.5 + 2e-5 * 2)
    assert P[2, 2] == pytest.approx(0.03 * 0.2 + 0.004 * 0.5 + 3e-5 * 2)
    assert P[0, 1] == P[0, 2] == P[1, 2] == 0.0

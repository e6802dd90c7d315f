"""The colour-landmark file: round trips (YAML and JSON) and one-line errors naming the key."""

from __future__ import annotations

import pytest

from slamio.camera.colour import DEFAULT_COLOURS, ColourOptions
from slamio.camera.landmark_file import LandmarkFileError, load_landmarks, options_from_dict, save_landmarks

SEED002 = """
# seed 002's three boards
landmarks:
  - {name: orange-triangle, id: 10, shape: triangle, width_m: 0.28, height_m: 0.243,
     hsv: [[[5, 120, 80], [20, 255, 255]]]}
  - {name: green-circle, id: 11, shape: circle, width_m: 0.24, height_m: 0.24, hsv: [[[40, 110, 50], [85, 255, 255]]]}
  - name: blue-rectangle
    id: 12
    shape: rectangle
    width_m: 0.30
    height_m: 0.405
    hsv: [[[100, 110, 50], [130, 255, 255]]]
checks: {size_tolerance: 0.25, erode_px: 4}
"""


def test_a_written_file_reads_back_the_same(tmp_path):
    options = ColourOptions(colours=DEFAULT_COLOURS, size_tolerance=0.3, uneven_rows=0.1)
    for name in ("landmarks.yaml", "landmarks.json"):
        path = tmp_path / name
        save_landmarks(path, options, comment="tuned on run 3")
        assert load_landmarks(path) == options
    assert (tmp_path / "landmarks.yaml").read_text().startswith("# fgslam colour landmarks")


def test_seed002_boards_from_yaml(tmp_path):
    path = tmp_path / "boards.yaml"
    path.write_text(SEED002)
    options = load_landmarks(path)
    assert [(c.name, c.landmark_id, c.shape) for c in options.colours] == [
        ("orange-triangle", 10, "triangle"), ("green-circle", 11, "circle"), ("blue-rectangle", 12, "rectangle")]
    assert options.colours[2].height_m == 0.405 and options.colours[0].radius_m == 0.0
    assert options.size_tolerance == 0.25 and options.erode_px == 4
    assert options.height_tolerance == ColourOptions().height_tolerance  # not in the file: the default


def _entry(**kw):
    entry = {"name": "red", "id": 0, "hsv": [[[0, 110, 60], [8, 255, 255]]]}
    entry.update(kw)
    return entry


@pytest.mark.parametrize("data,message", [
    ({"colours": []}, "'landmarks' list"),
    ({"landmarks": []}, "non-empty list"),
    ({"landmarks": [_entry(shape="sphere")]}, r"landmarks\[0\] \(red\)\.shape must be one of cylinder"),
    ({"landmarks": [_entry(hsv=[[[0, 110, 60], [200, 255, 255]]])]}, "H is 0-179"),
    ({"landmarks": [_entry(hsv=[[[170, 110, 60], [8, 255, 255]]])]}, "give two ranges"),
    ({"landmarks": [_entry(hsv=[[0, 110, 60]])]}, r"hsv\[0\] must be \[\[H, S, V\], \[H, S, V\]\]"),
    ({"landmarks": [_entry(width_m=0)]}, r"width_m must be > 0"),
    ({"landmarks": [_entry(id=-1)]}, r"\.id must be >= 0"),
    ({"landmarks": [_entry(), _entry(name="red2")]}, "same id: 0"),
    ({"landmarks": [_entry(colour="red")]}, "unknown key"),
    ({"landmarks": [{"id": 3, "hsv": []}]}, "needs 'name'"),
    ({"landmarks": [_entry()], "checks": {"size_tol": 0.3}}, "checks: unknown key"),
    ({"landmarks": [_entry()], "checks": {"erode_px": 2.5}}, "erode_px must be an integer"),
])
def test_mistakes_are_one_line_errors_naming_the_key(data, message):
    with pytest.raises(LandmarkFileError, match=message) as error:
        options_from_dict(data, "my.yaml")
    assert str(error.value).startswith("my.yaml: ") and "\n" not in str(error.value)


def test_unreadable_and_malformed_files(tmp_path):
    with pytest.raises(LandmarkFileError, match="cannot read"):
        load_landmarks(tmp_path / "missing.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("landmarks:\n  - name: red\n    hsv: [[[0, 1, 2]\n")
    with pytest.raises(LandmarkFileError, match=r"bad.yaml:\d+: not valid YAML"):
        load_landmarks(bad)


def test_the_example_in_the_docs_is_the_default():
    from pathlib import Path

    import yaml

    text = (Path(__file__).parents[1] / "docs" / "camera.md").read_text()
    start = text.index("```yaml\n# fgslam colour landmarks") + len("```yaml\n")
    assert options_from_dict(yaml.safe_load(text[start : text.index("```", start)]), "docs") == ColourOptions()

"""The colour-landmark file: which colours are landmarks, their ids, shapes and sizes, and the checks' tolerances.

YAML (or JSON, which is YAML too); ``fgslam detect --kind colour --landmarks FILE`` reads
it, ``fgslam tune-colours`` writes it. Every key but ``landmarks`` is optional::

    # fgslam colour landmarks (docs/camera.md)
    landmarks:
      - name: red
        id: 0                  # landmark id in the log (null: seen but not identified)
        shape: cylinder        # cylinder | circle | triangle | rectangle
        width_m: 0.10          # cylinder/circle: diameter; triangle: base; rectangle: width
        height_m: 0.40         # null: any height (not checked)
        hsv:                   # OpenCV scale: H 0-179, S and V 0-255; red wraps around H = 0
          - [[0, 110, 60], [8, 255, 255]]
          - [[170, 110, 60], [179, 255, 255]]
        min_area_px: 40
    checks:
      size_tolerance: 0.35     # |measured width / width_m - 1| at most
      height_tolerance: 0.15   # |measured height / height_m - 1| at most
      height_precision: 0.03   # no height when an end set by depth alone may be off by more (x height)
      depth_tolerance_m: 0.03  # body depth spread allowed beyond width/2 and the Kinect's steps
      depth_outliers: 0.05     # fraction of the body allowed outside that
      uneven_rows: 0.08        # cylinder, rectangle: fraction of rows allowed to stick out
      erode_px: 3              # depth is read this far inside the blob (misregistration)
      min_valid_depth_fraction: 0.3

A mistake names the file, the entry and the key, and says what to write
(:class:`LandmarkFileError`).
"""

from __future__ import annotations

import json
import os
from dataclasses import fields, replace
from pathlib import Path
from typing import Any

from slamio.camera.colour import ColourOptions, ColourSpec
from slamio.camera.colour_checks import SHAPES
from slamio.errors import InputFileError, read_text
from slamio.log.fields import MAX_ID
from slamio.safe_input import Document, parse_json, parse_yaml

#: The ``checks`` keys: ColourOptions fields a user may tune, with their types.
CHECK_KEYS = {
    "size_tolerance": float,
    "height_tolerance": float,
    "height_precision": float,
    "depth_tolerance_m": float,
    "depth_outliers": float,
    "uneven_rows": float,
    "erode_px": int,
    "min_valid_depth_fraction": float,
}
LANDMARK_KEYS = ("name", "id", "shape", "width_m", "height_m", "hsv", "min_area_px")


class LandmarkFileError(InputFileError):
    """A colour-landmark file that cannot be used; the message names the file (and line) and
    the key (``fgslam`` exits with status 2)."""


#: The largest value of a landmark file's numbers: a landmark id is a signed 32-bit integer
#: (as the run log's), sizes are metres (a landmark is not 100 m wide), areas pixels, and
#: the checks' tolerances far below 1e6.
MAX_VALUE = {"id": MAX_ID, "width_m": 100.0, "height_m": 100.0, "min_area_px": 10**9, "erode_px": 1000}
MAX_CHECK_VALUE = 1e6


def _number(path: str, where: str, value: Any, kind: type, minimum: float, inclusive: bool = False):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or (kind is int and not isinstance(value, int)):
        raise LandmarkFileError(f"{path}: {where} must be {'an integer' if kind is int else 'a number'}, got {value!r}")
    maximum = MAX_VALUE.get(where.rsplit(".", 1)[-1], MAX_CHECK_VALUE)
    if value < minimum or (value == minimum and not inclusive) or not value <= maximum:
        raise LandmarkFileError(f"{path}: {where} must be {'>=' if inclusive else '>'} {minimum} and at most "
                                f"{maximum}, got {value!r}")
    return kind(value)


def _hsv_ranges(path: str, where: str, value: Any) -> tuple:
    example = "e.g. [[[0, 110, 60], [8, 255, 255]]] (a list of [low, high] HSV triples)"
    if not isinstance(value, list) or not value:
        raise LandmarkFileError(f"{path}: {where} must be a non-empty list of [low, high] HSV ranges, {example}")
    out = []
    for k, pair in enumerate(value):
        ok = isinstance(pair, list) and len(pair) == 2 and all(
            isinstance(t, list) and len(t) == 3 and all(isinstance(x, int) and not isinstance(x, bool) for x in t)
            for t in pair)
        if not ok:
            raise LandmarkFileError(f"{path}: {where}[{k}] must be [[H, S, V], [H, S, V]] integers, {example}")
        lo, hi = pair
        for (h, s, v) in (lo, hi):
            if not (0 <= h <= 179 and 0 <= s <= 255 and 0 <= v <= 255):
                raise LandmarkFileError(f"{path}: {where}[{k}]: H is 0-179, S and V 0-255 (OpenCV's scale), got {pair}")
        if any(a > b for a, b in zip(lo, hi)):
            raise LandmarkFileError(
                f"{path}: {where}[{k}]: each low value must be <= its high value, got {pair} "
                "(for a red that wraps around H = 0, give two ranges: [0..8] and [170..179])")
        out.append((tuple(lo), tuple(hi)))
    return tuple(out)


def _refuse_unknown_keys(path: str, where: str, given: dict, known) -> None:
    unknown = sorted(set(given) - set(known), key=str)
    if unknown:
        raise LandmarkFileError(f"{path}: {where}: unknown key(s) {', '.join(map(str, unknown))}; "
                                f"known: {', '.join(known)}")


def _landmark(path: str, k: int, entry: Any) -> ColourSpec:
    where = f"landmarks[{k}]"
    if not isinstance(entry, dict):
        raise LandmarkFileError(f"{path}: {where} must be a mapping with keys {', '.join(LANDMARK_KEYS)}")
    _refuse_unknown_keys(path, where, entry, LANDMARK_KEYS)
    for key in ("name", "hsv"):
        if key not in entry:
            raise LandmarkFileError(f"{path}: {where} needs '{key}'")
    name = entry["name"]
    if not isinstance(name, str) or not name.strip():
        raise LandmarkFileError(f"{path}: {where}.name must be a non-empty string")
    where = f"landmarks[{k}] ({name})"
    landmark_id = entry.get("id")
    if landmark_id is not None:
        landmark_id = _number(path, f"{where}.id", landmark_id, int, 0, inclusive=True)
    shape = entry.get("shape", "cylinder")
    if shape not in SHAPES:
        raise LandmarkFileError(f"{path}: {where}.shape must be one of {', '.join(SHAPES)}, got {shape!r}")
    width_m = _number(path, f"{where}.width_m", entry.get("width_m", 0.10), float, 0.0)
    height_m = entry.get("height_m")
    if height_m is not None:
        height_m = _number(path, f"{where}.height_m", height_m, float, 0.0)
    min_area = _number(path, f"{where}.min_area_px", entry.get("min_area_px", 40), int, 1, inclusive=True)
    return ColourSpec(name, landmark_id, _hsv_ranges(path, f"{where}.hsv", entry["hsv"]), shape, width_m, height_m,
                      min_area)


def options_from_dict(data: Any, path: str = "<landmarks>", base: ColourOptions = ColourOptions(),
                      doc: Document | None = None) -> ColourOptions:
    """ColourOptions from a parsed landmark file (``base`` supplies what the file does not
    say); with ``doc`` (the file it was read from) errors name the line too."""

    def at(*keys) -> str:
        return doc.where(*keys) if doc is not None else path

    if not isinstance(data, dict) or "landmarks" not in data:
        raise LandmarkFileError(f"{path}: expected a mapping with a 'landmarks' list (see docs/camera.md)")
    _refuse_unknown_keys(path, "top level", data, ("landmarks", "checks"))
    entries = data["landmarks"]
    if not isinstance(entries, list) or not entries:
        raise LandmarkFileError(f"{at('landmarks')}: 'landmarks' must be a non-empty list")
    colours = tuple(_landmark(at("landmarks", k), k, e) for k, e in enumerate(entries))
    for attribute, label in (("name", "name"), ("landmark_id", "id")):
        values = [getattr(c, attribute) for c in colours if getattr(c, attribute) is not None]
        duplicates = sorted({v for v in values if values.count(v) > 1}, key=str)
        if duplicates:
            raise LandmarkFileError(f"{path}: two landmarks have the same {label}: {duplicates[0]!r}")
    checks = data.get("checks") or {}
    if not isinstance(checks, dict):
        raise LandmarkFileError(f"{at('checks')}: 'checks' must be a mapping of {', '.join(CHECK_KEYS)}")
    _refuse_unknown_keys(at("checks"), "checks", checks, tuple(CHECK_KEYS))
    values = {key: _number(at("checks", key), f"checks.{key}", checks[key], kind, 0.0, inclusive=True)
              for key, kind in CHECK_KEYS.items() if key in checks}
    return replace(base, colours=colours, **values)


def options_to_dict(options: ColourOptions) -> dict:
    """The landmark file's content for these options (the inverse of :func:`options_from_dict`)."""
    landmarks = []
    for c in options.colours:
        landmarks.append({
            "name": c.name, "id": c.landmark_id, "shape": c.shape, "width_m": c.width_m, "height_m": c.height_m,
            "hsv": [[list(lo), list(hi)] for lo, hi in c.hsv_ranges], "min_area_px": c.min_area_px,
        })
    known = {f.name for f in fields(ColourOptions)}
    return {"landmarks": landmarks, "checks": {key: getattr(options, key) for key in CHECK_KEYS if key in known}}


def load_landmarks(path: str | os.PathLike[str], base: ColourOptions = ColourOptions()) -> ColourOptions:
    """Read a landmark file (YAML or JSON)."""
    p = Path(path)
    text = read_text(p, "landmark file", "a landmark file is UTF-8 YAML or JSON text (see docs/camera.md; "
                     "fgslam tune-colours --out writes one)", LandmarkFileError)
    if p.suffix.lower() == ".json":  # as JSON: YAML 1.1 would read 1e308 as a string
        doc = parse_json(p, text, error=LandmarkFileError)
    else:  # YAML (or JSON in a .yaml file: JSON is YAML); NaN, .inf, aliases, deep nesting refused
        doc = parse_yaml(p, text, error=LandmarkFileError, what="YAML/JSON")
    return options_from_dict(doc.data, str(p), base, doc)


def save_landmarks(path: str | os.PathLike[str], options: ColourOptions, comment: str = "",
                   as_json: bool | None = None) -> None:
    """Write a landmark file: JSON for a ``.json`` name (or ``as_json``), YAML otherwise."""
    import yaml

    p = Path(path)
    data = options_to_dict(options)
    if as_json if as_json is not None else p.suffix.lower() == ".json":
        p.write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
        return
    header = "# fgslam colour landmarks (docs/camera.md): colours, ids, shapes, sizes and the checks' tolerances\n"
    if comment:
        header += "".join(f"# {line}\n" for line in comment.splitlines())
    p.write_text(header + yaml.safe_dump(data, sort_keys=False, default_flow_style=None), encoding="utf-8")


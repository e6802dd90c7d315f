"""Tuning the landmark colours on the user's own frames (``fgslam tune-colours``).

The colours in a landmark file are a guess until they meet the user's camera and lighting.
Tuning starts from the file's ranges **loosened** (hue widened by ``hue_widen`` each side,
saturation and value floors lowered), finds the landmarks in every frame with the same
checks as detection (shape, depth, width, height: :mod:`slamio.camera.colour` — so a
loosened range does not turn clutter into landmarks), and collects the hue, saturation and
value of each found landmark's body (its mask eroded, away from edges that mix with the
background). The tuned ranges cover 99 % of those pixels (0.5–99.5 % of the hue, measured
around the circular mean so red's wrap at H = 0 is no special case) plus 4 hue steps, with
saturation and value floors at 0.6 × their 1st percentile (room for a darker exposure). Tune
on frames that cover the lighting of the runs. A colour found in no
frame keeps its ranges.

Pure functions on numbers and masks; :mod:`fgslam.cli.tune_colours` reads the frames and writes
the file and the pictures.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from slamio.camera.colour import ColourOptions, ColourSpec, HsvRange, detect_colour_landmarks, eroded_body
from slamio.camera.model import CameraModel

HUES = 180  # OpenCV's hue scale


def hue_set(ranges: tuple[HsvRange, ...]) -> np.ndarray:
    """(180,) bool: the hues any of the ranges covers."""
    covered = np.zeros(HUES, dtype=bool)
    for (h0, _, _), (h1, _, _) in ranges:
        covered[h0 : h1 + 1] = True
    return covered


def hue_runs(covered: np.ndarray) -> list[tuple[int, int]]:
    """Contiguous [h0, h1] runs of a (180,) bool hue set (a run across H = 0 is two runs)."""
    runs, start = [], None
    for h in range(HUES):
        if covered[h] and start is None:
            start = h
        if start is not None and (h == HUES - 1 or not covered[h + 1]):
            runs.append((start, h))
            start = None
    return runs


def loosened(colour: ColourSpec, hue_widen: int = 12, saturation_floor: int = 60, value_floor: int = 40) -> ColourSpec:
    """The colour's ranges widened by ``hue_widen`` on each side (circularly), with the
    saturation and value floors lowered to at most the given ones."""
    covered = hue_set(colour.hsv_ranges)
    wide = covered.copy()
    for shift in range(1, hue_widen + 1):
        wide |= np.roll(covered, shift) | np.roll(covered, -shift)
    s_floor = min(saturation_floor, min(lo[1] for lo, _ in colour.hsv_ranges))
    v_floor = min(value_floor, min(lo[2] for lo, _ in colour.hsv_ranges))
    ranges = tuple(((h0, s_floor, v_floor), (h1, 255, 255)) for h0, h1 in hue_runs(wide))
    return replace(colour, hsv_ranges=ranges)


def tuned_ranges(hsv_pixels: np.ndarray, hue_margin: int = 4, floor_fraction: float = 0.6) -> tuple[HsvRange, ...]:
    """Ranges covering (N, 3) HSV pixels: hue 0.5–99.5 % around the circular mean ± ``hue_margin``,
    saturation and value from ``floor_fraction`` × their 1st percentile up to 255 (a darker
    exposure scales value down, and a paler one saturation: the floors leave room for both)."""
    h = hsv_pixels[:, 0].astype(float)
    angle = h * (2.0 * np.pi / HUES)
    mean = float(np.angle(np.mean(np.exp(1j * angle))) * HUES / (2.0 * np.pi)) % HUES
    deviation = (h - mean + HUES / 2) % HUES - HUES / 2
    lo = int(np.floor(mean + np.percentile(deviation, 0.5))) - hue_margin
    hi = int(np.ceil(mean + np.percentile(deviation, 99.5))) + hue_margin
    covered = np.zeros(HUES, dtype=bool)
    covered[np.arange(lo, hi + 1) % HUES] = True
    s_floor = int(max(20, floor_fraction * np.percentile(hsv_pixels[:, 1], 1.0)))
    v_floor = int(max(20, floor_fraction * np.percentile(hsv_pixels[:, 2], 1.0)))
    return tuple(((h0, s_floor, v_floor), (h1, 255, 255)) for h0, h1 in hue_runs(covered))


@dataclass
class ColourSamples:
    """What tuning saw of one landmark colour over the frames."""

    frames_found: int = 0
    pixels: list[np.ndarray] = field(default_factory=list)  # (n, 3) uint8 HSV per found landmark

    def stacked(self) -> np.ndarray:
        return np.concatenate(self.pixels) if self.pixels else np.zeros((0, 3), dtype=np.uint8)


def sample_frame(bgr: np.ndarray, depth_m: np.ndarray, camera: CameraModel, options: ColourOptions,
                 samples: dict[str, ColourSamples], erode_px: int = 2) -> None:
    """Find the landmarks of ``options`` (already loosened) in one frame; add their body pixels."""
    import cv2

    hsv = cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV)
    measured, _, _ = detect_colour_landmarks(bgr, depth_m, camera, options)
    for m in measured:
        body = eroded_body(m.blob, erode_px)
        sample = samples.setdefault(m.colour, ColourSamples())
        sample.frames_found += 1
        sample.pixels.append(hsv[body])


def tuned_options(options: ColourOptions, samples: dict[str, ColourSamples], min_pixels: int = 50) -> ColourOptions:
    """The options with each colour's ranges tuned to its samples (kept when there are too few)."""
    colours = []
    for colour in options.colours:
        pixels = samples.get(colour.name, ColourSamples()).stacked()
        colours.append(replace(colour, hsv_ranges=tuned_ranges(pixels)) if len(pixels) >= min_pixels else colour)
    return replace(options, colours=tuple(colours))

"""How precisely a camera measures an AprilTag's range, bearing and yaw: one physical model.

A tag of side ``s`` metres at range ``r``, seen by a pinhole camera of focal length ``fx``
pixels, is ``fx·s/r`` pixels wide. Its detector finds the four corners to about
``corner_sigma_px`` pixels, and everything the front-end reports follows from that:

- **bearing**: the centre moves by a fraction of a pixel, σ_b = g_b·σ_px/fx, independent of
  range and of how the tag is turned;
- **range**: the apparent size is off by the relative amount ε = σ_px·r/(fx·s), so the range
  it gives is off by r·ε: σ_r = g_r·r²·σ_px/(fx·s), growing when the tag is turned
  away (its image narrows by cos φ): the factor 1/cos(φ)^p_r;
- **yaw** (the direction the tag faces): it comes from the foreshortening, cos φ ≈
  width/height. An error ε in that ratio moves φ by ε/sin φ — large near a frontal view,
  where the foreshortening barely changes with φ (the two IPPE solutions ±φ are then
  nearly equally good) — and at φ = 0 by about √ε. σ_yaw = g_y·ε/√(sin²φ + g_y·ε).

φ is the viewing angle: between the tag's face normal and the direction from the tag to
the camera (0 = seen head on). The dimensionless gains g_b, g_r, p_r, g_y come from
frames rendered at known poses (where the corner precision is known too), the corner
precision of a real camera from real photos; ``scripts/measure_tag_noise.py`` measures
both and docs/camera.md lists the numbers. :data:`MEASURED_GAINS` are those numbers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class TagNoiseGains:
    """Dimensionless factors between the corner precision and the measured quantities' σ."""

    bearing: float  # g_b
    range: float  # g_r
    range_view_power: float  # p_r
    yaw: float  # g_y


#: Measured by ``scripts/measure_tag_noise.py`` on rendered frames (docs/camera.md).
MEASURED_GAINS = TagNoiseGains(bearing=0.63, range=0.72, range_view_power=0.0, yaw=0.62)

#: Corner precision of the chosen detector on real photos (pupil-labs robot camera, after
#: corner refinement): the reprojection residual of a square fitted to the four corners,
#: scaled for the two degrees of freedom the fit leaves (docs/camera.md).
REAL_CORNER_SIGMA_PX = 0.46


@dataclass(frozen=True)
class TagNoise:
    """σ of range, bearing and tag yaw for a tag of ``tag_size_m`` seen by a camera of ``fx_px``."""

    fx_px: float
    tag_size_m: float
    corner_sigma_px: float = REAL_CORNER_SIGMA_PX
    gains: TagNoiseGains = MEASURED_GAINS

    def __post_init__(self):
        if not (self.fx_px > 0 and self.tag_size_m > 0 and self.corner_sigma_px > 0):
            raise ValueError(f"need fx, tag size and corner sigma > 0, got {self.fx_px}, {self.tag_size_m}, "
                             f"{self.corner_sigma_px}")

    def relative_size_error(self, range_m):
        """ε = σ_px·r/(fx·s): the relative error of the tag's apparent size (floats or arrays)."""
        return self.corner_sigma_px * np.asarray(range_m, dtype=float) / (self.fx_px * self.tag_size_m)

    def sigma_bearing_rad(self, range_m=None, view_rad=None):
        value = self.gains.bearing * self.corner_sigma_px / self.fx_px
        return value if range_m is None else np.full(np.shape(range_m), value)

    def sigma_range_m(self, range_m, view_rad):
        r = np.asarray(range_m, dtype=float)
        cos_view = np.maximum(np.cos(np.asarray(view_rad, dtype=float)), 0.1)
        return self.gains.range * r * self.relative_size_error(r) / cos_view**self.gains.range_view_power

    def sigma_tag_yaw_rad(self, range_m, view_rad):
        g_eps = self.gains.yaw * self.relative_size_error(range_m)
        sin_view = np.sin(np.asarray(view_rad, dtype=float))
        return np.minimum(g_eps / np.sqrt(sin_view**2 + g_eps), math.pi)

    def describe(self) -> dict:
        """The model as a log header's observation-model entry."""
        return {
            "model": "measured AprilTag noise (slamio.camera.tag_noise): eps = corner_sigma_px*r/(fx_px*tag_size_m); "
            "sigma_bearing = g_b*corner_sigma_px/fx_px; sigma_range = g_r*r*eps/cos(view)^p_r; "
            "sigma_tag_yaw = g_y*eps/sqrt(sin(view)^2 + g_y*eps); view = angle between the tag's normal and "
            "the tag-to-camera direction; each observation carries its own sigmas",
            "fx_px": self.fx_px,
            "tag_size_m": self.tag_size_m,
            "corner_sigma_px": self.corner_sigma_px,
            "g_b": self.gains.bearing,
            "g_r": self.gains.range,
            "p_r": self.gains.range_view_power,
            "g_y": self.gains.yaw,
        }


def view_angle_rad(bearing_rad, tag_yaw_rad):
    """Angle between a tag's face normal and the tag→robot direction, from robot-frame values.

    The tag→robot direction in the robot frame is ``bearing + π``; the normal is ``tag_yaw``.
    """
    d = np.asarray(tag_yaw_rad, dtype=float) - (np.asarray(bearing_rad, dtype=float) + math.pi)
    return np.abs(np.arctan2(np.sin(d), np.cos(d)))

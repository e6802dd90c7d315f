"""Seed 002 §4.6 (Kinect landmark heights): the paper's ``gHeight`` and the exact geometry.

The paper measures a landmark's height from one Kinect frame: it finds the landmark's top
and bottom pixel rows, reads the depth at each, and passes the two depths ``d1, d2`` and
the pixel distance ``pd`` between the rows to ``gHeight``. Its listing (§4.6, MATLAB)::

    function gheight(d1,d2,pd)
    ds=min(d1,d2); db=max(d1,d2);
    theta=((pd*47)/480);               % degrees: 47° spread linearly over 480 rows
    db1=ds*cos(deg2rad(theta));         % the short ray projected onto the long one
    db2=db-db1;                         % the rest of the long ray
    dp=sqrt(ds power(2)-db1 power(2);   % (sic: one parenthesis is missing)
    ...
    h = sqrt(db2 power(2) + dp power(2))

The last line is not in the listing: the extracted text cuts the listing off after ``dp``
and prints ``h = sqrt(db2 power(2) + dp power(2))`` alone after the captions of Figures
4.7–4.14. We read it as the listing's last line. That is a **reconstruction**, but the
only one consistent with the paper's triangle (Figure 4.4's description: two rays from
the camera to the landmark's top and bottom, with the angle θ between them): ``dp`` is the
distance from the short ray's end to the long ray and ``db2`` the remaining length of the
long ray, so they are the legs of a right triangle whose hypotenuse joins the two ray ends
— the landmark's height. Algebraically it is the law of cosines,

    h² = ds² + db² − 2·ds·db·cos θ,

exact *if* ``d1, d2`` are the lengths of the two rays and θ is the true angle between them.
Neither holds for a Kinect:

1. **Depth is z-depth, not ray length.** The Kinect (SDK, OpenNI, libfreenect) reports the
   distance along the optical axis, ``z``; the ray to pixel row v is ``z·√(1 + ((v−c_y)/f_y)²)``
   long. For a vertical landmark and a level camera both ends have the *same* z, so the
   "triangle" is isosceles and gHeight returns ``2·z·sin(θ/2)``.
2. **Pixels are not angles.** The angle between rows is ``atan((v₂−c_y)/f_y) −
   atan((v₁−c_y)/f_y)``, not proportional to ``v₂ − v₁``.
3. **47° over 480 px is the wrong scale.** With the default Kinect intrinsics
   (f_y = 525 px, c_y = 239.5) one pixel at the centre spans 1/525 rad = 0.1091°, and 480
   rows span 2·atan(240/525) = 49.1°; the Kinect's nominal vertical field of view is 43°.
   The paper's 47/480 = 0.0979°/px is 10.3 % smaller than the centre value, so gHeight
   under-reads every small segment by about 10 %. (If ``pd`` is counted on the Kinect SDK's
   own 640×480 depth image — nominal f = 2 × 285.63 = 571.26 px, vertical FOV 45.6° — the
   scale error is 2.4 % instead; the paper does not say which image it counted rows on.)

:func:`exact_height_m` is the pinhole-geometry answer the paper's function approximates;
:func:`render_vertical_segment` makes test inputs for both. ``docs/estimators.md`` has the
measured error of gHeight. Every function here is numpy-vectorised and pure.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "G_HEIGHT_FOV_DEG",
    "G_HEIGHT_ROWS",
    "KINECT_FX",
    "KINECT_FY",
    "KINECT_CX",
    "KINECT_CY",
    "KINECT_ROWS",
    "g_height",
    "g_height_angle_deg",
    "exact_height_m",
    "ray_to_z_depth",
    "z_to_ray_depth",
    "angle_between_rows_rad",
    "render_vertical_segment",
    "rows_in_frame",
    "deviation_percent",
]

#: The paper's vertical field of view (degrees) and the image rows it is spread over.
G_HEIGHT_FOV_DEG = 47.0
G_HEIGHT_ROWS = 480

#: Default Kinect v1 intrinsics (the nominal ones TUM RGB-D uses): 640×480, fx = fy = 525.
KINECT_FX = 525.0
KINECT_FY = 525.0
KINECT_CX = 319.5
KINECT_CY = 239.5
KINECT_ROWS = 480


def g_height_angle_deg(pd, *, fov_deg: float = G_HEIGHT_FOV_DEG, rows: int = G_HEIGHT_ROWS):
    """The paper's pixel → angle map: ``θ = pd · 47 / 480`` degrees (linear in pixels)."""
    return np.asarray(pd, dtype=float) * fov_deg / rows


def g_height(d1, d2, pd, *, fov_deg: float = G_HEIGHT_FOV_DEG, rows: int = G_HEIGHT_ROWS):
    """The paper's ``gHeight(d1, d2, pd)``, line by line (see the module docstring).

    ``d1, d2`` are the depths read at the landmark's top and bottom pixels, in any unit
    (the paper's Kinect SDK gives millimetres; the height comes out in the same unit), and
    ``pd`` the number of pixel rows between them. The paper treats the depths as the lengths
    of the two rays and turns ``pd`` into the angle between them with 47° per 480 rows.
    ``fov_deg``/``rows`` default to the paper's numbers (they exist so the docs can show
    what other values would give). Arrays broadcast; returns a float for scalar inputs.
    """
    d1 = np.asarray(d1, dtype=float)
    d2 = np.asarray(d2, dtype=float)
    ds = np.minimum(d1, d2)
    db = np.maximum(d1, d2)
    theta = g_height_angle_deg(pd, fov_deg=fov_deg, rows=rows)
    db1 = ds * np.cos(np.deg2rad(theta))
    db2 = db - db1
    dp = np.sqrt(ds**2 - db1**2)  # ≥ 0 in floating point too: |db1| ≤ ds, rounding is monotone
    h = np.sqrt(db2**2 + dp**2)  # the reconstructed last line
    return float(h) if h.ndim == 0 else h


def ray_to_z_depth(ray, v, *, u=KINECT_CX, fx=KINECT_FX, fy=KINECT_FY, cx=KINECT_CX, cy=KINECT_CY):
    """z-depth (along the optical axis) of the point at pixel (u, v) whose ray has length ``ray``."""
    a = (np.asarray(u, dtype=float) - cx) / fx
    b = (np.asarray(v, dtype=float) - cy) / fy
    return np.asarray(ray, dtype=float) / np.sqrt(1.0 + a * a + b * b)


def z_to_ray_depth(z, v, *, u=KINECT_CX, fx=KINECT_FX, fy=KINECT_FY, cx=KINECT_CX, cy=KINECT_CY):
    """Length of the ray to the point at pixel (u, v) with z-depth ``z`` (inverse of the above)."""
    a = (np.asarray(u, dtype=float) - cx) / fx
    b = (np.asarray(v, dtype=float) - cy) / fy
    return np.asarray(z, dtype=float) * np.sqrt(1.0 + a * a + b * b)


def exact_height_m(
    v_top,
    v_bottom,
    depth_top_m,
    depth_bottom_m,
    *,
    depth_kind: str = "z",
    u=KINECT_CX,
    fx: float = KINECT_FX,
    fy: float = KINECT_FY,
    cx: float = KINECT_CX,
    cy: float = KINECT_CY,
):
    """Exact pinhole-geometry length of a segment from its end pixels' rows and depths.

    Both ends are back-projected through an ideal pinhole camera (image rows ``v`` grow
    downwards, columns ``u``; both ends in the same column ``u``, by default the principal
    column) and the 3-D distance between them is returned::

        X = (u − c_x)·z / f_x,   Y = (v − c_y)·z / f_y,   Z = z
        length = ‖(X, Y, Z)_top − (X, Y, Z)_bottom‖

    ``depth_kind="z"`` (default): the depths are **z-depths** — the distance along the
    optical axis, what a Kinect depth image holds. ``depth_kind="ray"``: they are ray
    lengths (camera centre to point), what gHeight's triangle assumes. A 3-D distance does
    not depend on the camera's pose, so this is the segment's true length — a vertical
    landmark's height — whatever the camera's height and pitch, as long as both ends are
    seen in column ``u``. Rows may be fractional and outside the image (the geometry does
    not care). Units follow the depths.
    """
    if depth_kind not in ("z", "ray"):
        raise ValueError(f"depth_kind must be 'z' or 'ray', got {depth_kind!r}")
    kw = dict(u=u, fx=fx, fy=fy, cx=cx, cy=cy)
    z_top = np.asarray(depth_top_m, dtype=float)
    z_bottom = np.asarray(depth_bottom_m, dtype=float)
    if depth_kind == "ray":
        z_top = ray_to_z_depth(z_top, v_top, **kw)
        z_bottom = ray_to_z_depth(z_bottom, v_bottom, **kw)
    a = (np.asarray(u, dtype=float) - cx) / fx
    dX = a * (z_top - z_bottom)
    dY = (np.asarray(v_top, dtype=float) - cy) * z_top / fy - (np.asarray(v_bottom, dtype=float) - cy) * z_bottom / fy
    dZ = z_top - z_bottom
    length = np.sqrt(dX * dX + dY * dY + dZ * dZ)
    return float(length) if length.ndim == 0 else length


def angle_between_rows_rad(v1, v2, *, fy: float = KINECT_FY, cy: float = KINECT_CY):
    """True angle between the rays through rows ``v1`` and ``v2`` of the principal column."""
    return np.abs(np.arctan((np.asarray(v2, float) - cy) / fy) - np.arctan((np.asarray(v1, float) - cy) / fy))


def render_vertical_segment(
    height_m,
    distance_m,
    *,
    camera_height_m: float = 0.0,
    fy: float = KINECT_FY,
    cy: float = KINECT_CY,
):
    """Image rows and depths of a vertical segment standing on the floor, exact pinhole model.

    The segment runs from the floor (height 0) up to ``height_m``, ``distance_m`` in front of
    a level camera (pitch 0) mounted ``camera_height_m`` above the floor, in the principal
    column. Returns ``(v_top, v_bottom, z_top, z_bottom, ray_top, ray_bottom)``: fractional
    rows (they may fall outside the image — see :func:`rows_in_frame`), z-depths (both equal
    ``distance_m``: the camera is level) and ray lengths.
    """
    h = np.asarray(height_m, dtype=float)
    z = np.asarray(distance_m, dtype=float)
    v_top = cy + fy * (camera_height_m - h) / z
    v_bottom = cy + fy * (camera_height_m - 0.0) / z + 0.0 * h
    z_top = z + 0.0 * h
    z_bottom = z + 0.0 * h
    ray_top = z_to_ray_depth(z_top, v_top, fy=fy, cy=cy)
    ray_bottom = z_to_ray_depth(z_bottom, v_bottom, fy=fy, cy=cy)
    return v_top, v_bottom, z_top, z_bottom, ray_top, ray_bottom


def rows_in_frame(*rows, image_rows: int = KINECT_ROWS):
    """True where every given row lies on the image (−0.5 ≤ v ≤ rows − 0.5)."""
    ok = np.ones(np.broadcast(*[np.asarray(r) for r in rows]).shape, dtype=bool)
    for r in rows:
        r = np.asarray(r, dtype=float)
        ok &= (r >= -0.5) & (r <= image_rows - 0.5)
    return ok


def deviation_percent(observed, actual):
    """The paper's "percentage of deviation" (Figures 5.1–5.3): ``100·(observed − actual)/actual``."""
    observed = np.asarray(observed, dtype=float)
    actual = np.asarray(actual, dtype=float)
    return 100.0 * (observed - actual) / actual

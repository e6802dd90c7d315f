"""Tests of ``ekf.kinect_height``: the paper's gHeight against exact pinhole geometry.

* gHeight line by line against a hand computation, and against the law of cosines it is;
* ``exact_height_m`` recovers rendered segments to 1e-9 (z-depths and ray lengths, and
  with a pitched, raised camera);
* gHeight's measured error on rendered segments (heights 0.2–1.0 m, distances 0.8–4 m,
  camera at floor height, pitch 0), with the bounds documented in docs/estimators.md;
* the paper's result tables: the only values the text gives inputs for are its
  "percentage of deviation" columns, which we recompute from its observed/actual heights.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from ekf.kinect_height import (
    KINECT_CY,
    KINECT_FY,
    angle_between_rows_rad,
    deviation_percent,
    exact_height_m,
    g_height,
    g_height_angle_deg,
    ray_to_z_depth,
    render_vertical_segment,
    rows_in_frame,
    z_to_ray_depth,
)

# The grid of the brief: heights 0.2–1.0 m, distances 0.8–4.0 m, camera height 0, pitch 0.
HEIGHTS, DISTANCES = np.meshgrid(np.linspace(0.2, 1.0, 33), np.linspace(0.8, 4.0, 65))


@pytest.fixture(scope="module")
def rendered():
    names = ("v_top", "v_bottom", "z_top", "z_bottom", "ray_top", "ray_bottom")
    arrays = dict(zip(names, render_vertical_segment(HEIGHTS, DISTANCES), strict=True))
    v_top, v_bottom = arrays["v_top"], arrays["v_bottom"]
    return dict(arrays, pd=np.abs(v_bottom - v_top), in_frame=rows_in_frame(v_top, v_bottom))


# --------------------------------------------------------------------------- gHeight itself


def test_g_height_line_by_line():
    """The listing of §4.6 evaluated by hand for d1 = 2100, d2 = 2000 (mm), pd = 60 px."""
    ds, db = 2000.0, 2100.0
    theta = 60 * 47 / 480  # 5.875°
    db1 = ds * math.cos(math.radians(theta))
    db2 = db - db1
    dp = math.sqrt(ds**2 - db1**2)
    h = math.sqrt(db2**2 + dp**2)
    assert g_height(2100.0, 2000.0, 60) == pytest.approx(h, rel=1e-14)
    assert g_height(2000.0, 2100.0, 60) == pytest.approx(h, rel=1e-14)  # order of d1, d2 irrelevant
    assert g_height_angle_deg(60) == pytest.approx(5.875)
    # it is the law of cosines with θ = pd·47/480 degrees
    assert h == pytest.approx(math.sqrt(ds**2 + db**2 - 2 * ds * db * math.cos(math.radians(theta))), rel=1e-12)
    # units follow the depths: millimetres in, millimetres out
    assert g_height(2.1, 2.0, 60) == pytest.approx(h / 1000.0, rel=1e-12)


def test_g_height_edge_cases_and_arrays():
    assert g_height(1500.0, 1500.0, 0) == 0.0
    assert g_height(1500.0, 1800.0, 0) == pytest.approx(300.0)  # zero angle: the depth difference
    out = g_height(np.array([1.0, 2.0]), np.array([1.0, 2.0]), np.array([10.0, 20.0]))
    assert out.shape == (2,) and np.all(np.isfinite(out))


def test_g_height_is_exact_given_ray_lengths_and_the_true_angle(rendered):
    """The triangle is right: fed ray lengths and a pd whose 47°/480 angle is the true
    angle between the rays, gHeight returns the true height. Its errors come from its inputs."""
    true_angle_deg = np.degrees(angle_between_rows_rad(rendered["v_top"], rendered["v_bottom"]))
    pd_equivalent = true_angle_deg * 480 / 47
    h = g_height(rendered["ray_top"], rendered["ray_bottom"], pd_equivalent)
    np.testing.assert_allclose(h, HEIGHTS, rtol=1e-9)


# --------------------------------------------------------------------------- the exact model


def test_exact_height_recovers_rendered_segments(rendered):
    h = exact_height_m(rendered["v_top"], rendered["v_bottom"], rendered["z_top"], rendered["z_bottom"])
    np.testing.assert_allclose(h, HEIGHTS, rtol=0, atol=1e-9)
    h = exact_height_m(
        rendered["v_top"], rendered["v_bottom"], rendered["ray_top"], rendered["ray_bottom"], depth_kind="ray"
    )
    np.testing.assert_allclose(h, HEIGHTS, rtol=0, atol=1e-9)


def test_rendering_matches_the_pinhole_model():
    v_top, v_bottom, z_top, z_bottom, ray_top, ray_bottom = render_vertical_segment(0.5, 2.0)
    assert v_bottom == pytest.approx(KINECT_CY)  # the foot is at camera height: the image centre row
    assert v_top == pytest.approx(KINECT_CY - KINECT_FY * 0.5 / 2.0)
    assert z_top == z_bottom == 2.0  # a level camera sees a vertical segment at one z-depth
    assert ray_top == pytest.approx(math.hypot(2.0, 0.5))
    assert ray_bottom == pytest.approx(2.0)
    assert ray_to_z_depth(z_to_ray_depth(1.7, 100.0, u=50.0), 100.0, u=50.0) == pytest.approx(1.7)


def test_exact_height_does_not_depend_on_the_camera_pose():
    """A camera 0.3 m up, pitched 10° down, segment off-axis: the 3-D length is still exact."""
    rng = np.random.default_rng(2)
    pitch = math.radians(10.0)
    for _ in range(20):
        height, distance = rng.uniform(0.2, 1.0), rng.uniform(0.8, 4.0)
        # world: x right, y up, z forward; camera at (0, 0.3, 0) looking along +z, pitched down
        ends = np.array([[0.0, 0.0, distance], [0.0, height, distance]]) - np.array([0.0, 0.3, 0.0])
        c, s = math.cos(pitch), math.sin(pitch)
        # camera frame (x right, y down, z forward) after pitching the camera down by `pitch`
        y_down = -(ends[:, 1] * c + ends[:, 2] * s)
        z = -ends[:, 1] * s + ends[:, 2] * c
        v = KINECT_CY + KINECT_FY * y_down / z
        got = exact_height_m(v[1], v[0], z[1], z[0])
        assert got == pytest.approx(height, abs=1e-9)
        got = exact_height_m(v[1], v[0], z_to_ray_depth(z[1], v[1]), z_to_ray_depth(z[0], v[0]), depth_kind="ray")
        assert got == pytest.approx(height, abs=1e-9)


def test_rows_in_frame():
    assert rows_in_frame(0.0, 479.0)
    assert not rows_in_frame(-1.0, 100.0)
    assert not rows_in_frame(10.0, 480.0)


# --------------------------------------------------------------------------- gHeight's error


def relative_error(rendered, depth):
    d_top, d_bottom = rendered[f"{depth}_top"], rendered[f"{depth}_bottom"]
    return (g_height(d_top, d_bottom, rendered["pd"]) - HEIGHTS) / HEIGHTS


def test_g_height_error_with_kinect_z_depths(rendered):
    """What the paper fed it: Kinect depth is z-depth. For a vertical segment and a level
    camera both ends share one z, so gHeight = 2·z·sin(θ/2) while the truth is z·pd/f_y:
    it reads low by 10.28 % for small segments (the 47°/480 px scale against f_y = 525)
    to 10.91 % for a segment filling the upper half of the frame (pd = 240)."""
    err = relative_error(rendered, "z")
    inside = rendered["in_frame"]
    assert inside.mean() > 0.8
    # closed form of the ratio: g/h = 2·f_y·sin(θ/2)/pd
    theta = np.radians(g_height_angle_deg(rendered["pd"]))
    np.testing.assert_allclose(err + 1.0, 2 * KINECT_FY * np.sin(theta / 2) / rendered["pd"], rtol=1e-12)
    small_angle_limit = math.radians(47 / 480) * KINECT_FY - 1.0  # −10.279 %
    assert small_angle_limit == pytest.approx(-0.10279, abs=1e-5)
    assert np.all(err[inside] < small_angle_limit + 1e-12)
    assert err[inside].max() == pytest.approx(small_angle_limit, abs=2e-4)  # smallest pd
    half_frame = 2 * KINECT_FY * math.sin(math.radians(240 * 47 / 480) / 2) / 240 - 1.0
    assert half_frame == pytest.approx(-0.10907, abs=1e-5)
    assert err[inside].min() >= half_frame - 1e-12
    worst = np.unravel_index(np.argmin(np.where(inside, err, np.inf)), err.shape)
    assert rendered["pd"][worst] == pytest.approx(240.0, abs=3.0)  # the segment fills half the frame
    # in metres: at most 0.11 m short on a 1 m segment
    assert np.max(np.abs(err * HEIGHTS)[inside]) < 0.11


def test_g_height_error_if_fed_ray_lengths(rendered):
    """Even with the depths its triangle assumes (ray lengths), the linear 47°/480 px map
    reads low: by 10.2 % for small segments far away (small pd), by only 4.1 % for a
    segment filling half the frame (there the atan compression of real pixels partly
    cancels the scale error)."""
    err = relative_error(rendered, "ray")
    inside = rendered["in_frame"]
    assert np.all(err[inside] < 0)
    assert err[inside].min() == pytest.approx(-0.1020, abs=5e-4)
    assert err[inside].max() == pytest.approx(-0.0407, abs=5e-4)
    small = np.unravel_index(np.argmin(np.where(inside, err, np.inf)), err.shape)
    assert HEIGHTS[small] == pytest.approx(0.2) and DISTANCES[small] == pytest.approx(4.0)


def test_g_height_error_with_the_sdk_depth_intrinsics():
    """If pd is counted on the Kinect SDK's 640×480 depth image (nominal f = 571.26 px),
    the scale error of 47°/480 px shrinks to 2.4 % for small segments."""
    fy = 2 * 285.63
    v_top, v_bottom, z_top, z_bottom, *_ = render_vertical_segment(0.3, 3.0, fy=fy)
    pd = v_bottom - v_top
    err = g_height(z_top, z_bottom, pd) / 0.3 - 1.0
    assert err == pytest.approx(2 * fy * math.sin(math.radians(pd * 47 / 480) / 2) / pd - 1.0, abs=1e-12)
    assert math.radians(47 / 480) * fy - 1.0 == pytest.approx(-0.0237, abs=1e-4)  # small-angle limit
    assert err == pytest.approx(-0.024, abs=1e-3)


# --------------------------------------------------------------------------- the paper's tables


PAPER_TABLES = [  # (observed cm, actual cm, printed percentage of deviation), Figures 5.1–5.3
    (24.69187, 24.30, 1.613), (42.69025, 40.50, 5.409), (24.38301, 24.00, 1.596),
    (26.49091, 24.00, 10.379), (44.16669, 40.50, 9.054), (26.1389, 24.00, 8.912),
    (24.54875, 24.30, 1.024), (42.605, 40.5, 5.198), (26.38484, 24.30, 8.58),
    (24.77077, 24.00, 3.212), (43.02866, 40.5, 6.244), (24.77824, 24.30, 1.969),
    (24.55982, 24.0, 2.33), (42.98286, 40.5, 6.131), (26.19158, 24.30, 7.784),
    (25.90652, 24.0, 7.94), (43.66396, 40.5, 7.812), (24.59224, 24.30, 1.203),
]  # fmt: skip


def test_the_papers_deviation_columns_recompute():
    """The text gives no (d1, d2, pd) for its measurements, so gHeight's outputs cannot be
    reproduced; its deviation columns can, to the rounding of the print (≤ 0.005 points)."""
    observed, actual, printed = (np.array(c) for c in zip(*PAPER_TABLES))
    np.testing.assert_allclose(deviation_percent(observed, actual), printed, atol=0.005)
    # every measured height is an over-estimate (+1.0 … +10.4 %), while gHeight's geometry
    # alone reads low: the paper's errors came from elsewhere (pixel picking, depth noise)
    assert np.all(printed > 0)


def test_seed002_shapes_on_rendered_frames_read_low_with_gheight_and_right_with_the_pinhole():
    # the experiment of scripts/seed002_shapes.py, one frame per shape at 2 m (docs/seeds.md)
    from slamio.camera.accuracy import ROBOT_POSE, kinect_camera, world_point
    from slamio.camera.colour import DEFAULT_COLOURS, ColourOptions
    from slamio.camera.detect import FrontEnd, FrontEndConfig
    from slamio.camera.render import CYLINDER_BGR, BoardSpec, Scene, render
    from slamio.camera.sources import Frame

    shapes = (("circle", "red", 0.24, 0.240), ("triangle", "green", 0.24, 0.243), ("rectangle", "blue", 0.20, 0.405))
    by_name = {c.name: c for c in DEFAULT_COLOURS}
    specs = tuple(dataclasses.replace(by_name[c], shape=s, width_m=w, height_m=h) for s, c, w, h in shapes)
    camera = kinect_camera()
    fronts = {m: FrontEnd(camera, FrontEndConfig(kind="colour", colour=ColourOptions(colours=specs, height_method=m)))
              for m in ("gheight", "pinhole")}
    rng = np.random.default_rng(0)
    x, y = world_point(2.0, 0.0)
    facing = math.atan2(ROBOT_POSE[1] - y, ROBOT_POSE[0] - x)
    for shape, colour, width, height in shapes:
        board = BoardSpec(shape, x, y, width, height, facing, CYLINDER_BGR[colour])
        image = render(camera, ROBOT_POSE, Scene(boards=(board,)), depth_model="kinect", noise_sigma=2.0, rng=rng,
                       supersample=3)
        frame = Frame(0.0, 0, "rendered", image.bgr, image.depth_m)
        (g,) = fronts["gheight"].process(frame).observations
        (p,) = fronts["pinhole"].process(frame).observations
        assert -0.16 < g.height_m / height - 1 < -0.08, shape  # gHeight reads low (docs/estimators.md)
        assert abs(p.height_m / height - 1) < 0.04, shape

"""AprilTags: the detector on real photos, corner conventions, IPPE flips, robot-frame geometry."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from slamio.camera.accuracy import corner_set_errors, match_detections, read_corner_list
from slamio.camera.apriltag import (
    AprilTagDetector,
    TagDetectorError,
    TagPose,
    apriltag_to_opencv_corners,
    choose_tag_pose,
    TagDetection,
    estimate_tag_pose,
    fit_lines,
    neighbour_intersections,
    opencv_threads,
    refine_tag_corners,
    tag_geometry,
    tag_object_points,
)
from slamio.camera.model import CameraModel, T_robot_camera_from_mount, kinect_v1_default, rotation_y
from slamio.camera.render import Scene, TagSpec, project_world_points, render, tag_corners_world
from slamio.camera.tag_passes import TagPasses, already_found, front_end_detector
from slamio.camera.tag_union import ListedTag, found_by_a_setup, read_union, score_against_union, write_union

PHOTOS = Path(__file__).resolve().parent / "data" / "apriltag-photos"
NASA = sorted(PHOTOS.glob("nasa_*.jpg"))


def grey(path):
    import cv2

    return cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)


@pytest.fixture(scope="module")
def detector():
    return AprilTagDetector()  # the first pass alone: tag36h11, quad_decimate 1.0, refine_edges off


@pytest.fixture(scope="module")
def front_end():
    return front_end_detector()  # what fgslam detect uses: AprilTag 3 on the image enlarged 1.75x, then cv2.aruco


def test_real_photos_are_there():
    assert len(NASA) == 3, f"expected the three NASA photos in {PHOTOS}"


def test_nasa_photos_recall_false_detections_and_corner_error(detector):
    total = None
    for image in NASA:
        listed = read_corner_list(image.with_suffix(".txt"))
        found = [(d.tag_id, d.corners_px) for d in detector.detect(grey(image))]
        result = match_detections(found, listed, image=image.name)
        if total is None:
            total = result
        else:
            total.add(result)
    print(f"\nNASA photos: {total.found}/{total.listed} listed tags found, "
          f"{len(total.false_detections)} false detections, corner error max {total.max_corner_error_px:.3f} px "
          f"mean {total.mean_corner_error_px:.3f} px; missed: {[(m[0], m[1], m[2].round(1).tolist()) for m in total.missed]}")
    assert total.listed == 47
    assert total.found >= 46
    assert not total.false_detections
    assert total.max_corner_error_px <= 0.5


def _union_score(detector):
    union = read_union(PHOTOS / "nasa_union.txt")
    found = {image.name: [(d.tag_id, d.centre_px) for d in detector.detect(grey(image))] for image in NASA}
    return score_against_union(found, union, found_by_a_setup)


def test_union_listing_is_every_tag_eight_setups_find():
    union = read_union(PHOTOS / "nasa_union.txt")
    assert sum(found_by_a_setup(t) for t in union) == 61
    assert sum("apriltag3" in t.found_by for t in union) == 46  # the first pass's own share
    assert {t.image for t in union} == {p.name for p in NASA}


def test_first_pass_alone_finds_46_of_the_union(detector):
    score = _union_score(detector)
    assert (score.found, score.counted) == (46, 61)
    assert not score.not_listed and not score.duplicates


def test_front_end_finds_55_of_the_union_and_nothing_else(front_end):
    score = _union_score(front_end)
    print(f"\nNASA photos, front-end detector: {score.found}/{score.counted} of the union, "
          f"{len(score.not_listed)} detections outside it; missed {[(m[0][5:16], m[2].round().tolist()) for m in score.missed]}")
    assert score.counted == 61
    assert score.found >= 55  # 57 measured with pupil-apriltags 1.0.4 and OpenCV 5.0
    assert not score.not_listed, f"detections matching no listed tag: {score.not_listed}"
    assert not score.duplicates


def test_pupil_photos_front_end_finds_the_same_ids(detector, front_end):
    # no tag id that the signs do not carry, and no tag the first pass found is lost
    for path in sorted(PHOTOS.glob("pupil_*.png")):
        image = grey(path)
        first = sorted(d.tag_id for d in detector.detect(image))
        both = sorted(d.tag_id for d in front_end.detect(image))
        assert set(first) <= set(both), path.name
        assert len(both) == len(set(both)), f"{path.name}: a tag found twice"
        extra = set(both) - set(first)
        assert extra <= ({60, 82, 318, 328, 387} if path.name == "pupil_test_image.png"
                         else {22, 24, 58, 85, 144, 198}), f"{path.name}: unexpected ids {extra}"


def test_union_listing_round_trip_and_scoring(tmp_path):
    union = [ListedTag("a.jpg", 0, np.array([100.0, 50.0]), 20.0, ["apriltag3", "aruco"]),
             ListedTag("a.jpg", 3, np.array([300.0, 60.0]), 12.0, ["reference"])]
    write_union(tmp_path / "u.txt", union, "test listing")
    back = read_union(tmp_path / "u.txt")
    assert [(t.image, t.tag_id, t.found_by) for t in back] == [(t.image, t.tag_id, t.found_by) for t in union]
    assert np.allclose(back[0].centre_px, [100.0, 50.0]) and back[1].side_px == 12.0
    # id 0 within 0.3 x 20 px = 6 px; id 3 within 3 px (a small tag); id 0 twice; an unlisted id 5
    found = {"a.jpg": [(0, (105.0, 50.0)), (3, (302.0, 61.0)), (0, (101.0, 51.0)), (5, (100.0, 50.0))]}
    score = score_against_union(found, back, found_by_a_setup)
    assert (score.counted, score.found, score.found_other) == (1, 1, 1)
    assert len(score.duplicates) == 1 and [x[1] for x in score.not_listed] == [5]
    far = score_against_union({"a.jpg": [(0, (107.0, 50.0))]}, back, found_by_a_setup)
    assert far.found == 0 and len(far.not_listed) == 1 and len(far.missed) == 1
    (tmp_path / "bad.txt").write_text("a.jpg, 0, 1.0\n")
    with pytest.raises(ValueError, match="bad.txt:1"):
        read_union(tmp_path / "bad.txt")


def test_pupil_photos_only_known_ids_and_plausible_poses(detector):
    # the ids printed on the signs of these scenes (read once from the photos)
    scenes = {"pupil_test_image.png": ({60, 82, 318, 328, 387}, 336.7755634193813, 333.3575643300718,
                                       336.02729840829176, 212.77376312080065)}
    for k in range(1, 11):
        scenes[f"pupil_test_image_multiple_{k:02d}.png"] = (
            {22, 24, 58, 85, 144, 198}, 338.563277422543, 336.45495347495824, 338.939280638548, 230.486982216255)
    errors = []
    for name, (ids, fx, cx, fy, cy) in scenes.items():
        cam = CameraModel(640, 480, np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]]))
        for d in detector.detect(grey(PHOTOS / name)):
            assert d.tag_id in ids, f"{name}: unexpected tag id {d.tag_id}"
            poses = estimate_tag_pose(d.corners_px, 0.065, cam)
            assert poses and 0.05 < np.linalg.norm(poses[0].t_camera_tag_m) < 3.0
            errors.append(poses[0].reprojection_error_px)
    # signs on bent cards in imperfectly undistorted frames: most tags fit a square well, a few do not
    print(f"\npupil photos: {len(errors)} tags, reprojection error median {np.median(errors):.2f} px, "
          f"max {max(errors):.2f} px")
    assert len(errors) >= 50
    assert np.median(errors) < 0.5 and max(errors) < 5.0


def test_corner_order_and_pixel_convention_on_a_rendered_tag(detector):
    cam = kinect_v1_default(T_robot_camera_from_mount(z_m=0.2))
    tag = TagSpec(11, 1.5, 0.1, 0.25, math.pi - 0.3, 0.16)
    image = render(cam, (0.0, 0.0, 0.0), Scene(tags=(tag,)), supersample=3)
    import cv2

    g = cv2.cvtColor(image.bgr, cv2.COLOR_BGR2GRAY)
    (d,) = detector.detect(g)
    truth = project_world_points(cam, (0.0, 0.0, 0.0), tag_corners_world(tag))  # TL, TR, BR, BL
    assert d.tag_id == 11
    assert np.abs(d.corners_px - truth).max() < 0.8  # same order, same convention, binarised corners
    refined = refine_tag_corners(g, d.corners_px, cam)
    assert np.abs(refined - truth).max() < 0.25


@pytest.mark.parametrize("upsample", [1.75, 2.0])
def test_upsampled_detection_maps_corners_back(upsample):
    # the enlarged image's corners come back in the original pixels, as accurate as the first pass's or better
    cam = kinect_v1_default(T_robot_camera_from_mount(z_m=0.2))
    tag = TagSpec(11, 1.5, 0.1, 0.25, math.pi - 0.3, 0.16)
    import cv2

    g = cv2.cvtColor(render(cam, (0.0, 0.0, 0.0), Scene(tags=(tag,)), supersample=3).bgr, cv2.COLOR_BGR2GRAY)
    truth = project_world_points(cam, (0.0, 0.0, 0.0), tag_corners_world(tag))
    (d,) = AprilTagDetector(upsample=upsample).detect(g)
    assert d.tag_id == 11 and np.abs(d.corners_px - truth).max() < 0.5
    (d,) = front_end_detector(upsample=upsample).detect(g)  # the aruco pass adds nothing on top
    assert np.abs(refine_tag_corners(g, d.corners_px, cam) - truth).max() < 0.25


@pytest.mark.parametrize("distance_m, turn_rad", [(1.0, 0.0), (1.5, -0.7), (2.5, 0.7), (3.5, 0.35)])
def test_refined_corners_of_turned_tags_against_the_truth(detector, distance_m, turn_rad):
    # the four edges are sampled and fitted together; each corner is where its two edge lines meet
    cam = kinect_v1_default(T_robot_camera_from_mount(z_m=0.2))
    tag = TagSpec(11, distance_m, 0.1, 0.2, math.pi + turn_rad, 0.16)
    import cv2

    g = cv2.cvtColor(render(cam, (0.0, 0.0, 0.0), Scene(tags=(tag,)), supersample=3).bgr, cv2.COLOR_BGR2GRAY)
    truth = project_world_points(cam, (0.0, 0.0, 0.0), tag_corners_world(tag))
    (d,) = detector.detect(g)
    refined = refine_tag_corners(g, d.corners_px, cam)
    assert np.abs(refined - truth).max() < 0.25
    assert np.abs(refined - truth).max() <= np.abs(d.corners_px - truth).max()


def test_edge_lines_and_their_intersections_in_closed_form():
    # points spread symmetrically about each side of a known quadrilateral: the fitted lines are its
    # sides, and neighbouring lines meet at its corners
    corners = np.array([[10.0, 12.0], [52.0, 8.0], [58.0, 49.0], [6.0, 55.0]])
    rng = np.random.default_rng(3)
    point_sets = []
    for k in range(4):
        a, b = corners[k], corners[(k + 1) % 4]
        t = np.linspace(0.2, 0.8, 9)
        normal = np.array([a[1] - b[1], b[0] - a[0]]) / np.linalg.norm(b - a)
        offsets = rng.normal(0.0, 0.3, 9)
        points = a + t[:, None] * (b - a)
        point_sets.append(np.vstack([points + offsets[:, None] * normal, points - offsets[:, None] * normal]))
    centres, directions = fit_lines(point_sets)
    assert np.allclose(np.linalg.norm(directions, axis=1), 1.0)
    # line k runs from corner k to corner k+1, so lines k-1 and k meet at corner k
    assert np.abs(neighbour_intersections(centres, directions) - corners).max() < 1e-9
    assert neighbour_intersections(centres, np.tile([1.0, 0.0], (4, 1))) is None  # parallel lines


def test_passes_keep_the_first_detection_of_each_tag():
    # a later pass adds a tag only when its centre is not within half a side of one already found
    def tag(tag_id, x, y, side=20.0):
        h = side / 2
        return TagDetection(tag_id, "tag36h11", np.array([[x - h, y - h], [x + h, y - h], [x + h, y + h], [x - h, y + h]]))

    class Fixed:
        family = "tag36h11"

        def __init__(self, tags):
            self.tags = tags

        def detect(self, grey):
            return list(self.tags)

    first = [tag(0, 100, 100), tag(0, 140, 100)]
    again = tag(0, 108, 100)  # the first tag seen by the second pass, 8 px off: within half a side
    new = tag(3, 100, 125)  # 25 px away: another tag
    found = TagPasses([Fixed(first), Fixed([again, new])]).detect(np.zeros((8, 8), np.uint8))
    assert [(t.tag_id, t.centre_px.tolist()) for t in found] == [(0, [100.0, 100.0]), (0, [140.0, 100.0]),
                                                                  (3, [100.0, 125.0])]
    assert found[0] is first[0]  # the earlier pass's corners are kept
    assert not already_found(new, [])
    assert already_found(again, first)


def test_opencv_threads_are_set_inside_and_restored_after():
    import cv2

    before = cv2.getNumThreads()
    with opencv_threads(1):
        assert cv2.getNumThreads() == 1
    assert cv2.getNumThreads() == before


def test_a_far_small_tag_is_found_by_the_front_end_only(detector, front_end):
    # a 0.16 m tag at 10 m: 8.4 pixels wide with fx = 525 (on 156 renders of such tags at 5-11 m, turned
    # 0-52°, the first pass found 69, the front-end 87: docs/camera.md)
    cam = kinect_v1_default(T_robot_camera_from_mount(z_m=0.2))
    tag = TagSpec(5, 10.0, 0.3, 0.2, math.pi, 0.16)
    import cv2

    g = cv2.cvtColor(render(cam, (0.0, 0.0, 0.0), Scene(tags=(tag,)), supersample=3).bgr, cv2.COLOR_BGR2GRAY)
    truth = project_world_points(cam, (0.0, 0.0, 0.0), tag_corners_world(tag))
    assert detector.detect(g) == []
    (d,) = front_end.detect(g)
    print(f"\n8-pixel tag: corner error {np.abs(d.corners_px - truth).max():.2f} px")
    assert d.tag_id == 5 and np.abs(d.corners_px - truth).max() < 0.6


def test_library_corners_become_opencv_order():
    # the AprilTag library: CCW from the upright tag's top-right, pixel corner at (0, 0)
    library = np.array([[280.0, 100.0], [120.0, 100.0], [120.0, 260.0], [280.0, 260.0]])
    assert np.allclose(apriltag_to_opencv_corners(library),
                       [[119.5, 99.5], [279.5, 99.5], [279.5, 259.5], [119.5, 259.5]])


def test_corner_sets_match_whatever_the_order():
    a = np.array([[0, 0], [10, 0], [10, 10], [0, 10.0]])
    assert corner_set_errors(a, a[[2, 1, 0, 3]] + 0.1).max() == pytest.approx(0.1 * math.sqrt(2))


def _pose_camera(distance, yaw_in_view):
    """A tag straight ahead of the camera at ``distance``, face turned by ``yaw_in_view``."""
    R_flip = np.diag([1.0, -1.0, -1.0])  # tag x right, y up, z towards the camera
    return rotation_y(yaw_in_view) @ R_flip, np.array([0.0, 0.0, distance])


def test_both_ippe_solutions_come_back_and_the_best_is_the_truth():
    cam = kinect_v1_default()
    R, t = _pose_camera(1.5, math.radians(35))
    corners = cam.project(tag_object_points(0.16) @ R.T + t)
    poses = estimate_tag_pose(corners, 0.16, cam)
    assert len(poses) >= 2
    assert poses[0].reprojection_error_px < 1e-6 < poses[1].reprojection_error_px
    assert np.allclose(poses[0].R_camera_tag, R, atol=1e-6) and np.allclose(poses[0].t_camera_tag_m, t, atol=1e-6)


def test_a_fronto_parallel_tag_still_gets_its_pose():
    # OpenCV 5.0's IPPE_SQUARE returns a wrong rotation for an exactly frontal square; SQPnP saves it
    cam = kinect_v1_default()
    R, t = _pose_camera(2.0, 0.0)
    corners = cam.project(tag_object_points(0.16) @ R.T + t)
    best = estimate_tag_pose(corners, 0.16, cam)[0]
    assert best.reprojection_error_px < 1e-3
    assert np.allclose(best.t_camera_tag_m, t, atol=1e-6)


def test_flip_resolved_towards_an_upright_tag():
    T = T_robot_camera_from_mount(z_m=0.2)
    R, t = _pose_camera(3.0, 0.0)
    tilted = rotation_y(0.0) @ np.array([[1, 0, 0], [0, math.cos(0.5), -math.sin(0.5)], [0, math.sin(0.5), math.cos(0.5)]])
    upright = TagPose(R, t, 0.30)
    flipped = TagPose(tilted @ R, t, 0.25)  # fits a little better, but tilted 29° from vertical
    chosen, ambiguous = choose_tag_pose([flipped, upright], T)
    assert ambiguous and chosen is upright
    chosen, ambiguous = choose_tag_pose([flipped, upright], T, upright=False)
    assert ambiguous and chosen is flipped
    clear, ambiguous = choose_tag_pose([TagPose(R, t, 0.05), TagPose(tilted @ R, t, 0.9)], T)
    assert not ambiguous and clear.reprojection_error_px == 0.05


def test_geometry_in_the_robot_frame():
    # camera 0.1 m ahead of the robot centre at 0.2 m; a tag 2 m ahead of the camera facing it
    T = T_robot_camera_from_mount(x_m=0.1, z_m=0.2)
    R, t = _pose_camera(2.0, 0.0)
    g = tag_geometry(TagPose(R, t, 0.0), T)
    assert g.range_m == pytest.approx(2.1) and g.bearing_rad == pytest.approx(0.0, abs=1e-12)
    assert abs(g.tag_yaw_rad) == pytest.approx(math.pi)  # its face points back at the robot
    assert g.height_m == pytest.approx(0.2) and g.normal_tilt_rad == pytest.approx(0.0, abs=1e-12)
    # the same tag seen from a camera turned 30° left: bearing +30° (counter-clockwise), yaw turned too
    T_left = T_robot_camera_from_mount(yaw_rad=math.radians(30))
    g = tag_geometry(TagPose(R, t, 0.0), T_left)
    assert math.degrees(g.bearing_rad) == pytest.approx(30.0)
    assert math.degrees(g.tag_yaw_rad) == pytest.approx(30.0 - 180.0)


def test_unknown_family_is_a_user_error():
    with pytest.raises(TagDetectorError):
        AprilTagDetector("tag99h99")
    with pytest.raises(TagDetectorError):
        AprilTagDetector(backend="magic")
    with pytest.raises(TagDetectorError, match="upsample"):
        AprilTagDetector(upsample=0.5)
    with pytest.raises(TagDetectorError, match="second pass"):
        front_end_detector(second_pass="magic")
    # a family OpenCV's aruco does not know: AprilTag 3 alone
    assert len(front_end_detector("tagStandard41h12").detectors) == 1
    assert len(front_end_detector().detectors) == 2


def test_detectors_can_be_made_and_dropped_repeatedly():
    # pupil-apriltags 1.0.4 frees in the wrong order and corrupts the heap; our subclass must not
    for _ in range(20):
        AprilTagDetector().detect(np.zeros((64, 64), np.uint8))
    assert sum(np.eye(8).sum() for _ in range(2000)) == 16000


def test_aruco_backend_for_comparison():
    import cv2

    dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
    image = np.full((300, 300), 255, np.uint8)
    image[70:230, 70:230] = cv2.aruco.generateImageMarker(dictionary, 42, 160)
    (d,) = AprilTagDetector(backend="aruco").detect(image)
    assert d.tag_id == 42 and np.abs(d.corners_px - [[69.5, 69.5], [229.5, 69.5], [229.5, 229.5], [69.5, 229.5]]).max() < 1.0


def test_quad_thresholds_are_set_in_the_library_detector_only_for_the_enlarged_pass():
    import ctypes

    from slamio.camera.apriltag import QUAD_THRESHOLD_DEFAULTS, _quad_threshold_struct
    from slamio.camera.tag_passes import ENLARGED_MIN_CLUSTER_PIXELS, ENLARGED_MIN_WHITE_BLACK_DIFF

    def thresholds(detector):
        head = ctypes.cast(detector._detector.tag_detector_ptr, ctypes.POINTER(_quad_threshold_struct())).contents
        return head.qtp.min_white_black_diff, head.qtp.min_cluster_pixels, head.qtp.max_nmaxima

    enlarged = front_end_detector().detectors[0]
    assert thresholds(enlarged) == (ENLARGED_MIN_WHITE_BLACK_DIFF, ENLARGED_MIN_CLUSTER_PIXELS, 10)
    native = front_end_detector(upsample=1.0).detectors[0]
    assert thresholds(native) == (QUAD_THRESHOLD_DEFAULTS["min_white_black_diff"],
                                  QUAD_THRESHOLD_DEFAULTS["min_cluster_pixels"], 10)


def test_a_binding_laid_out_otherwise_keeps_the_default_thresholds_with_a_warning(monkeypatch):
    import slamio.camera.apriltag as apriltag

    monkeypatch.setattr(apriltag, "QUAD_THRESHOLD_DEFAULTS", {**apriltag.QUAD_THRESHOLD_DEFAULTS, "max_nmaxima": 11})
    with pytest.warns(RuntimeWarning, match="default quad thresholds"):
        detector = apriltag.AprilTagDetector(min_white_black_diff=40, min_cluster_pixels=40)
    assert not detector.quad_thresholds_set
    import cv2

    image = np.full((300, 300), 255, np.uint8)
    image[70:230, 70:230] = cv2.aruco.generateImageMarker(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11), 7, 160)
    assert [d.tag_id for d in detector.detect(image)] == [7]


@pytest.mark.parametrize("settings", [{"nthreads": 0}, {"nthreads": -1}, {"quad_decimate": 0.5}, {"quad_decimate": float("nan")}])
def test_settings_the_c_detector_would_divide_by_are_refused(settings):
    """0 threads or a decimation below 1 once killed the process with a floating-point exception."""
    from slamio.camera.apriltag import AprilTagDetector, TagDetectorError

    with pytest.raises(TagDetectorError, match="must be"):
        AprilTagDetector(**settings)

"""The aruco pass's own identification against OpenCV's: real photos, rendered markers, Otsu, warp."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from slamio.camera.aruco_codes import (
    ArucoCandidates,
    family_codes,
    identify_quads,
    otsu_thresholds,
    warp_quads,
)

PHOTOS = Path(__file__).resolve().parent / "data" / "apriltag-photos"
DICTIONARY = "DICT_APRILTAG_36h11"


def front_end_parameters():
    """The front-end's aruco pass settings (slamio.camera.tag_passes)."""
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_NONE
    params.adaptiveThreshWinSizeMin = params.adaptiveThreshWinSizeMax = 3
    params.minMarkerPerimeterRate = 0.1
    return params


def real_frames():
    """The NASA photos, their 640 × 480 crops, the robot-camera photos (grey)."""
    nasa = [cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for p in sorted(PHOTOS.glob("nasa_*.jpg"))]
    crops = [np.ascontiguousarray(g[r:r + 480, c:c + 640]) for g in nasa
             for r, c in ((0, 0), ((g.shape[0] - 480) // 2, (g.shape[1] - 640) // 2), (g.shape[0] - 480, g.shape[1] - 640))]
    pupil = [cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for p in sorted(PHOTOS.glob("pupil_*.png"))]
    return nasa + crops + pupil


def by_id_and_centre(pairs):
    return {(int(i), tuple(np.round(c.mean(axis=0), 3))): c for i, c in pairs}


def test_identification_matches_opencv_on_real_photos():
    """Same tags, same corners as cv2.aruco's own identification, on every real frame shipped."""
    params = front_end_parameters()
    opencv = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11), params)
    ours = ArucoCandidates(params, 6)
    codes = family_codes(DICTIONARY)
    total = 0
    for grey in real_frames():
        corners, ids, _ = opencv.detectMarkers(grey)
        theirs = by_id_and_centre([] if ids is None else zip(ids.ravel(), (c.reshape(4, 2) for c in corners)))
        mine = by_id_and_centre(identify_quads(grey, ours.quads(grey), codes))
        assert mine.keys() == theirs.keys()
        for key in mine:
            np.testing.assert_allclose(mine[key], theirs[key], atol=1e-4)
        total += len(mine)
    assert total >= 100  # the photos hold well over a hundred tag sightings


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_rendered_markers_identified_with_their_id_and_top_left_corner(seed):
    """Markers drawn by OpenCV at known ids, turned by 0–3 quarter turns: id and corner order recovered."""
    rng = np.random.default_rng(seed)
    codes = family_codes(DICTIONARY)
    dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
    for _ in range(10):
        tag_id = int(rng.integers(len(codes.codes)))
        marker = dictionary.generateImageMarker(tag_id, 80, borderBits=1)
        image = np.full((120, 120), 255, np.uint8)
        image[20:100, 20:100] = marker
        turns = int(rng.integers(4))
        image = np.rot90(image, turns).copy()
        # the upright marker's corners in OpenCV's order, turned the same way (np.rot90 turns counter-clockwise)
        upright = np.array([[20, 20], [99, 20], [99, 99], [20, 99]], float)
        turned = upright.copy()
        for _ in range(turns):
            turned = np.stack([turned[:, 1], 119 - turned[:, 0]], axis=1)
        # hand the quad over starting from another corner, clockwise as OpenCV's candidates are
        start = int(rng.integers(4))
        found = identify_quads(image, np.roll(turned, -start, axis=0)[None], codes)
        assert len(found) == 1
        assert found[0][0] == tag_id
        np.testing.assert_allclose(found[0][1], turned)


def test_nothing_identified_in_a_blank_or_noisy_quad():
    codes = family_codes(DICTIONARY)
    rng = np.random.default_rng(3)
    noise = rng.integers(0, 256, (100, 100)).astype(np.uint8)
    quad = np.array([[[10, 10], [90, 10], [90, 90], [10, 90]]], float)
    assert identify_quads(np.zeros((100, 100), np.uint8), quad, codes) == []
    assert identify_quads(noise, quad, codes) == []
    assert identify_quads(noise, np.zeros((0, 4, 2)), codes) == []


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_otsu_threshold_binarises_as_opencv(seed):
    rng = np.random.default_rng(seed)
    patch = rng.integers(0, 256, (32, 32)).astype(np.uint8)
    if rng.random() < 0.5:  # two populations, as a tag's cells are
        patch = np.where(rng.random((32, 32)) < 0.4, rng.integers(0, 60, (32, 32)),
                         rng.integers(150, 256, (32, 32))).astype(np.uint8)
    _, binary = cv2.threshold(patch, 125, 255, cv2.THRESH_BINARY | cv2.THRESH_OTSU)
    ours = patch > otsu_thresholds(patch[None])[0]
    np.testing.assert_array_equal(ours, binary > 0)


@pytest.mark.parametrize("seed", range(5))
def test_warp_matches_opencv_warp_perspective(seed):
    """Nearest-neighbour warp of random quads, partly outside the image, against cv2.warpPerspective."""
    rng = np.random.default_rng(seed)
    grey = rng.integers(0, 256, (120, 160)).astype(np.uint8)
    quads = rng.uniform(-10, 170, (8, 4, 2))
    quads[:, :, 1] *= 120 / 180
    quads = np.array([q[np.argsort(np.arctan2(*(q - q.mean(axis=0)).T[::-1]))] for q in quads])  # clockwise on screen
    ours = warp_quads(grey, quads, 32)
    square = np.float32([[0, 0], [31, 0], [31, 31], [0, 31]])
    agree = []
    for quad, warped in zip(quads, ours):
        M = cv2.getPerspectiveTransform(quad.astype(np.float32), square)
        theirs = cv2.warpPerspective(grey, M, (32, 32), flags=cv2.INTER_NEAREST)
        agree.append(np.mean(warped == theirs))
    # OpenCV maps with fixed-point arithmetic: a pixel whose source lies on a half-pixel may round the other way
    assert min(agree) >= 0.99
    assert np.mean(agree) >= 0.999

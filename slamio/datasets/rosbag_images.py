"""Camera images in a bag → tag corners, through fgslam's own AprilTag detector.

``fgslam import rosbag --image-topic T`` reads ``sensor_msgs/Image`` (encodings ``mono8``,
``8UC1``, ``bgr8``, ``rgb8``, ``8UC3``, ``bgra8``, ``rgba8``) or ``sensor_msgs/CompressedImage``
(JPEG or PNG, decoded by OpenCV) and finds tags in each frame with the detector of ``fgslam
detect`` (:func:`slamio.camera.tag_passes.front_end_detector`: AprilTag 3 on the image enlarged
1.75 times, then OpenCV's aruco pass for what it missed), drops a tag within a cell of the image
border and refines the corners of the rest on the image
(:func:`slamio.camera.detect.tag_corners_for_pose`). Each tag's corners then take the path of
a bag's own corner detections (:mod:`slamio.datasets.rosbag_corners`: the pose through the
camera model and the tag's size, the reprojection check, σ from the corner noise), so an
image topic and an ``apriltag_msgs`` topic of the same frames give the same observations.

Refused, naming the topic and message: a depth image (``16UC1``, ``32FC1``, or a
``compressedDepth`` CompressedImage: it holds no tag pattern), an encoding not listed above
(Bayer, YUV, 16-bit), a frame whose size is not the camera's. A compressed frame that OpenCV
cannot decode is skipped and counted (``images_undecodable``).
"""

from __future__ import annotations

from collections import Counter
from typing import Any, Callable

import numpy as np

from slamio.camera.model import CameraModel
from slamio.datasets.rosbag_read import BagFormatError

__all__ = ["DEPTH_ENCODINGS", "IMAGE_ENCODINGS", "BagImageTags", "grey_from_image_message"]

#: sensor_msgs/Image encodings read, and their channels (8-bit each).
IMAGE_ENCODINGS = {"mono8": 1, "8UC1": 1, "bgr8": 3, "rgb8": 3, "8UC3": 3, "bgra8": 4, "rgba8": 4}
#: Encodings of depth images: refused (a depth image has no tag pattern to detect).
DEPTH_ENCODINGS = ("16UC1", "32FC1")


class ImageRefused(ValueError):
    """An image message that no frame of its topic can be read from (the reason names the fix)."""


def _message_bytes(msg: Any) -> np.ndarray:
    """An image message's ``data`` as uint8 (rosbags gives a numpy array or bytes)."""
    return np.frombuffer(msg.data if isinstance(msg.data, np.ndarray) else bytes(msg.data), dtype=np.uint8)


def _grey_from_raw(msg: Any) -> np.ndarray:
    encoding = str(msg.encoding)
    if encoding in DEPTH_ENCODINGS:
        raise ImageRefused(f"is a depth image (encoding {encoding}): tags are found in grey or colour images; "
                           "name the camera's colour or mono image topic with --image-topic")
    if encoding not in IMAGE_ENCODINGS:
        raise ImageRefused(f"has encoding {encoding!r}; fgslam reads {', '.join(IMAGE_ENCODINGS)} (republish it, "
                           "e.g. with image_proc, as mono8 or bgr8)")
    channels = IMAGE_ENCODINGS[encoding]
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    data = _message_bytes(msg)
    if h <= 0 or w <= 0 or step < w * channels or data.size < h * step:
        raise ImageRefused(f"says {w}×{h} pixels, {step} bytes a row ({encoding}) but holds {data.size} bytes")
    pixels = data[:h * step].reshape(h, step)[:, :w * channels].reshape(h, w, channels)
    if channels == 1:
        return np.ascontiguousarray(pixels[:, :, 0])
    import cv2

    code = {("rgb8", 3): cv2.COLOR_RGB2GRAY, ("rgba8", 4): cv2.COLOR_RGBA2GRAY, ("bgra8", 4): cv2.COLOR_BGRA2GRAY}
    return cv2.cvtColor(np.ascontiguousarray(pixels), code.get((encoding, channels), cv2.COLOR_BGR2GRAY))


def grey_from_image_message(msg: Any) -> np.ndarray | None:
    """The 8-bit grey image of a ``sensor_msgs/Image`` or ``CompressedImage`` message; None for a
    compressed frame OpenCV cannot decode; :class:`ImageRefused` for a depth or unread encoding."""
    if hasattr(msg, "encoding"):
        return _grey_from_raw(msg)
    import cv2

    fmt = str(getattr(msg, "format", ""))
    if "compressedDepth" in fmt or any(d in fmt for d in DEPTH_ENCODINGS):
        raise ImageRefused(f"is a compressed depth image (format {fmt!r}): tags are found in grey or colour images; "
                           "name the camera's colour or mono image topic with --image-topic")
    data = _message_bytes(msg)
    return cv2.imdecode(data, cv2.IMREAD_GRAYSCALE) if data.size else None


class BagImageTags:
    """The tags of each image message of a bag's image topics (``cameras``: topic → camera),
    counting frames, tags and skipped frames; ``progress(done,
    total, label)`` is called after every frame (``total``: the image messages of all topics)."""

    def __init__(self, path: str, cameras: dict[str, CameraModel], family: str = "tag36h11", total: int = 0,
                 progress: Callable[[int, int, str], None] | None = None):
        from slamio.camera.tag_passes import front_end_detector

        self.path, self.cameras, self.total, self.progress = path, cameras, total, progress
        self.detector = front_end_detector(family)
        self.counts: dict[str, Counter] = {topic: Counter() for topic in cameras}
        self.frames = 0

    def __call__(self, topic: str, index: int, msg: Any) -> list[tuple[int, np.ndarray]]:
        """(tag id, 4×2 corners in the MIT detector's order, as ``apriltag_msgs`` carries them)."""
        from slamio.camera.detect import tag_corners_for_pose

        camera, counts = self.cameras[topic], self.counts[topic]
        try:
            grey = grey_from_image_message(msg)
        except ImageRefused as exc:
            raise BagFormatError(self.path, topic, str(exc), index) from None
        counts["frames"] += 1
        tags: list[tuple[int, np.ndarray]] = []
        if grey is None:
            counts["images_undecodable"] += 1
        elif (mismatch := camera.size_mismatch(grey.shape[1], grey.shape[0])) is not None:
            raise BagFormatError(self.path, topic, f"{mismatch} ({camera.name or 'the camera given'}): "
                                 "give this camera's calibration", index)
        else:
            for det in self.detector.detect(grey):
                corners, note = tag_corners_for_pose(grey, det, camera)
                if corners is None:
                    counts[note] += 1
                    continue
                if note:
                    counts[note] += 1
                counts["tags"] += 1
                tags.append((det.tag_id, corners[::-1].copy()))  # OpenCV's TL, TR, BR, BL → MIT's BL, BR, TR, TL
        self.frames += 1
        if self.progress is not None:
            self.progress(self.frames, self.total, "images")
        return tags

    def summary(self) -> dict[str, dict[str, int]]:
        """Per topic: frames, tags found, and what was skipped (no times: a log file is reproducible)."""
        return {topic: dict(sorted(c.items())) for topic, c in self.counts.items()}

"""Camera front-end: AprilTags and Kinect colour landmarks → run-log observations.

- :mod:`slamio.camera.model`    intrinsics, distortion and mount from a ROS camera_info YAML
- :mod:`slamio.camera.apriltag` tag detection (AprilTag 3), sub-pixel corners, IPPE pose
- :mod:`slamio.camera.colour`   HSV blobs, their checks, depth encodings, range/bearing/height (seeds 000, 002)
- :mod:`slamio.camera.colour_checks` the pure maths of those checks (shape, width, depth, height)
- :mod:`slamio.camera.landmark_file` the colour-landmark file the user edits (YAML/JSON)
- :mod:`slamio.camera.sources`  TUM RGB-D folders, image folders, VideoCapture, live Kinect
- :mod:`slamio.camera.detect`   frames → :class:`slamio.log.Observation`, named rejections
- :mod:`slamio.camera.render`   a ray-casting renderer of tags and cylinders, for tests
- :mod:`slamio.camera.accuracy` errors vs distance on rendered frames (``python -m slamio.camera.accuracy``)
- :mod:`slamio.camera.composite` rendered landmarks pasted into real RGB-D frames, and their score

OpenCV (``opencv-python-headless``), ``pupil-apriltags`` and ``PyYAML`` are imported by the
modules that need them, so ``import slamio`` stays light. Documentation: docs/camera.md.
"""

from slamio.camera.model import CameraConfigError, CameraModel, load_camera, save_camera

__all__ = ["CameraConfigError", "CameraModel", "load_camera", "save_camera"]

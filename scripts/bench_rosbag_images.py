"""Benchmark: ``fgslam import rosbag --image-topic`` on a bag of rendered frames — time per
image and the observations' errors against the render's truth.

A ROS 1 bag is written (rosbags' own writer, in a temporary folder) of a robot driving 1.5 m
towards a wall of four 0.16 m tag36h11 tags (slamio.camera.render, known tag poses), one
camera at the Kinect v1's default intrinsics and mount, ``--frames`` frames of
``--width``×``--height`` pixels as ``sensor_msgs/Image`` bgr8 (or ``--compressed`` JPEG), with
nav_msgs/Odometry at the same stamps. Then :func:`slamio.datasets.rosbag.import_rosbag`
reads it with ``image_topic`` and the camera; printed: frames, tags found, CPU seconds per
frame of the whole import (``time.process_time``, one thread: on a busy machine the wall
clock says more about the neighbours), and the range / bearing errors of every observation
against the truth (max and RMS) with their median σ.

Usage: ``.venv/bin/python -m scripts.bench_rosbag_images [--frames N] [--width W --height H] [--compressed]``.
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from pathlib import Path

from scripts.common import one_blas_thread

one_blas_thread()

import numpy as np  # noqa: E402  (after BLAS is set to one thread)

EPOCH_NS = 1_700_000_000 * 10**9
PERIOD_NS = 100_000_000
TOPIC = "/cam/image_raw"


def _scene():
    from slamio.camera.render import Scene, TagSpec

    return Scene(tags=tuple(TagSpec(i, 3.0, y, 0.3, math.pi - 0.15 * i, size_m=0.16)
                            for i, y in enumerate((-0.6, -0.2, 0.2, 0.6))))


def _write_bag(path: Path, camera, frames: int, compressed: bool):
    import cv2
    from rosbags.rosbag1 import Writer

    from slamio.camera.render import render
    from slamio.datasets.rosbag import MessageFactory, apriltag_typestore

    store = apriltag_typestore(1)
    make = MessageFactory(store, 1)
    T = store.types
    poses = [(1.5 * k / max(frames - 1, 1), 0.0, 0.1 * math.sin(k / 3)) for k in range(frames)]
    with Writer(path) as writer:
        odom = writer.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=store)
        msgtype = "sensor_msgs/msg/CompressedImage" if compressed else "sensor_msgs/msg/Image"
        image = writer.add_connection(TOPIC + ("/compressed" if compressed else ""), msgtype, typestore=store)
        for k, pose in enumerate(poses):
            t = EPOCH_NS + k * PERIOD_NS
            writer.write(odom, t, make.serialize(make.odometry(t, pose, None, "odom", "base_link")))
            bgr = render(camera, pose, _scene(), supersample=2).bgr
            if compressed:
                data = np.frombuffer(cv2.imencode(".jpg", bgr)[1].tobytes(), dtype=np.uint8)
                msg = T[msgtype](header=make.header(t, "cam"), format="jpeg", data=data)
            else:
                msg = T[msgtype](header=make.header(t, "cam"), height=bgr.shape[0], width=bgr.shape[1],
                                 encoding="bgr8", is_bigendian=0, step=bgr.shape[1] * 3, data=bgr.ravel())
            writer.write(image, t + 1000, make.serialize(msg))
    return poses


def main(argv=None) -> int:
    from slamio.camera.model import CameraModel, kinect_v1_default
    from slamio.datasets.rosbag import import_rosbag
    from slamio.log import Observation

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=20)
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=480)
    ap.add_argument("--compressed", action="store_true")
    args = ap.parse_args(argv)
    kinect = kinect_v1_default()
    s = args.width / kinect.width_px
    K = kinect.K.copy()
    K[:2] *= s
    camera = CameraModel(args.width, args.height, K, T_robot_camera=kinect.T_robot_camera, name="kinect")
    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(tmp) / "images.bag"
        poses = _write_bag(bag, camera, args.frames, args.compressed)
        started = time.process_time()
        header, records = import_rosbag(bag, odom_topic="/odom", image_topic=_topic(args), camera=camera,
                                        tag_size_m=0.16, T_robot_camera=camera.T_robot_camera)
        cpu_s = time.process_time() - started
    tags = {t.tag_id: t for t in _scene().tags}
    errors, sigmas = [], []
    for o in (r for r in records if isinstance(r, Observation)):
        x, y, th = poses[round(o.stamp_s * 1e9 / PERIOD_NS)]
        dx, dy = tags[o.landmark_id].x_m - x, tags[o.landmark_id].y_m - y
        r = math.hypot(dx, dy)
        b = math.atan2(dy, dx) - th
        errors.append((o.range_m - r, math.remainder(o.bearing_rad - b, 2 * math.pi)))
        sigmas.append((o.sigma_range_m, o.sigma_bearing_rad))
    e, sg = np.array(errors), np.array(sigmas)
    summary = header.source["images"]
    print(f"{args.frames} frames {args.width}x{args.height} {'jpeg' if args.compressed else 'bgr8'}: {summary}")
    print(f"CPU {cpu_s / args.frames * 1e3:.0f} ms per frame (whole import, one thread)")
    print(f"{len(e)} observations: range error max {np.abs(e[:, 0]).max():.4f} m rms {np.sqrt(np.mean(e[:, 0]**2)):.4f} m "
          f"(median sigma {np.median(sg[:, 0]):.4f} m); bearing error max {np.abs(e[:, 1]).max() * 1e3:.2f} mrad "
          f"rms {np.sqrt(np.mean(e[:, 1]**2)) * 1e3:.2f} mrad (median sigma {np.median(sg[:, 1]) * 1e3:.2f} mrad)")
    return 0


def _topic(args) -> str:
    return TOPIC + ("/compressed" if args.compressed else "")


if __name__ == "__main__":
    raise SystemExit(main())

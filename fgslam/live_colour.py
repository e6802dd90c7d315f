"""``fgslam live`` with colour landmarks: the simulated Kinect of a hardware-in-the-loop run.

:func:`simulated_kinect` is :func:`fgslam.live.simulated_camera`'s colour twin: seed 000's
red, green and blue cylinders stand in three corners of seed 004's arena (clear of the
square and octagon paths), a Kinect 0.10 m ahead of the robot's centre at 0.30 m renders
them (colour and Kinect-quantised depth) from the simulated Create's true pose at the
instant each pose is made, and the colour front-end with the user's landmark file finds
them. A real Kinect goes through :func:`colour_front_end` with ``--frames kinect:N``.
"""

from __future__ import annotations

import numpy as np

from slamio.camera.colour import ColourOptions
from slamio.log import Odometry, TruthLandmark

#: Where the cylinders stand in the arena, by landmark colour name (metres; 0.35 m from two walls).
ARENA_CYLINDER_XY = {"red": (0.35, 0.35), "green": (2.70, 0.35), "blue": (2.70, 2.70)}


def colour_front_end(camera, options: ColourOptions):
    from slamio.camera.detect import FrontEnd, FrontEndConfig

    return FrontEnd(camera, FrontEndConfig(kind="colour", colour=options))


def simulated_kinect(sim, options: ColourOptions = ColourOptions(), *, supersample: int = 1,
                     pixel_noise: float = 2.0, seed: int = 0, scene=None, camera=None):
    """``(grab_for, front_end, truth_landmarks)`` for a simulated Kinect seeing the arena's cylinders.

    Each landmark of ``options`` named in :data:`ARENA_CYLINDER_XY` is placed there with its
    width and height (0.40 m when the file gives none) and rendered in that colour. A
    ``scene`` (e.g. the clutter room's, :meth:`slamio.clutter.ClutterWorld.scene`) replaces
    the arena: its cylinders with an id are the truth; ``camera`` replaces the Kinect's mount.
    """
    from slamio.camera.model import T_robot_camera_from_mount, kinect_v1_default
    from slamio.camera.render import CYLINDER_BGR, CylinderSpec, Scene, render
    from slamio.camera.sources import Frame

    cylinders = tuple(
        CylinderSpec(*ARENA_CYLINDER_XY[c.name], 0.5 * c.width_m, c.height_m or 0.40, CYLINDER_BGR[c.name], c.name,
                     c.landmark_id)
        for c in options.colours if c.name in ARENA_CYLINDER_XY and c.name in CYLINDER_BGR
    )
    if scene is None:
        scene = Scene(cylinders=cylinders)
    else:
        cylinders = tuple(c for c in scene.cylinders if c.landmark_id is not None)
    if camera is None:
        camera = kinect_v1_default(T_robot_camera_from_mount(x_m=0.10, z_m=0.30))
    front_end = colour_front_end(camera, options)
    rng = np.random.default_rng(seed)  # used only in the camera worker

    def grab_for(index: int, odometry: Odometry, true_pose=None):
        pose = sim.true_pose if true_pose is None else true_pose  # now, or the truth the loop just wrote

        def grab():
            frame = render(camera, pose, scene, supersample=supersample, depth_model="kinect",
                           noise_sigma=pixel_noise, rng=rng)
            return Frame(odometry.stamp_s, index, f"sim:{index}", frame.bgr, frame.depth_m)

        return grab

    truth = [TruthLandmark(c.landmark_id, c.x_m, c.y_m, c.height_m) for c in cylinders if c.landmark_id is not None]
    return grab_for, front_end, truth

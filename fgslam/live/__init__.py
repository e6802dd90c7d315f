"""``fgslam live``: drive the Create on the iSAM2 pose, see landmarks, smooth and record.

One process, three threads, one log:

* **The control loop** (the caller's thread) is the recorder's
  (:func:`slamio.create.record.record`): it reads the Create's sensor stream, runs the safety
  monitor and its watchdog, sends wheel commands and writes odometry records. The live loop
  rides on it through :class:`LiveLoop` (its ``hooks``) and steers it with a
  :class:`WaypointFollower` that closes the loop on the smoothed pose.
* **The camera worker** grabs a frame when asked and runs the landmark front-end
  (:class:`slamio.camera.detect.FrontEnd`) on it.
* **The smoother worker** feeds each pose (odometry + observations) to
  :class:`fgslam.smoother.Isam2Smoother` and publishes the pose and its covariance.

How one pose is made:

1. The control loop writes odometry record k (everything the wheels did since record k−1)
   and, in the same breath, asks the camera worker for a frame: the frame belongs to pose k.
   If the worker is still busy with an earlier frame the request is refused (``skipped``).
2. While that frame is being processed no further odometry record is written — the wheel
   readings keep arriving and accumulate into record k+1 (odometry is *batched*), so a slow
   frame delays a pose but never the serial link. The observations are written to the log
   right after record k as soon as they come back; a frame that takes longer than
   ``frame_timeout_s`` is given up (``dropped``).
3. Pose k goes to the smoother worker's queue. The smoother never holds up the control
   loop: the follower steers on the newest smoothed pose composed with the odometry since
   (:class:`PoseTracker`), whatever pose that is. Each smoother step's wall time is written
   to the log as a ``live_step`` record.

Safety is the recorder's: a bump, a wheel drop, a lost serial link, the watchdog or Ctrl-C
stops the wheels first and the log (flushed after every record) is kept. Any exception in a
worker is raised in the control loop, whose link exit stops the wheels before the log is
closed. The log is an ordinary run log: ``fgslam run LOG`` replays it with every estimator.

The package, one part of that per file: :mod:`~fgslam.live.steering` (settings, waypoints,
the follower, the pose tracker), :mod:`~fgslam.live.workers` (the camera and smoother
workers, the simulation's lockstep), :mod:`~fgslam.live.loop` (the recorder's hooks) and
:mod:`~fgslam.live.run` (the simulated camera and :func:`run_live`, which wires them up).
Import everything from ``fgslam.live``.
"""

from __future__ import annotations

from fgslam.live.loop import (
    LatestFrame,
    LiveLoop,
    LiveResult,
)
from fgslam.live.run import (
    LIVE_SIM_RANGE_SIGMA_PER_M2,
    LIVE_SIM_SIGMA_BEARING_RAD,
    LIVE_SIM_SIGMA_TAG_YAW_RAD,
    LIVE_SIM_TAG_SIZE_M,
    LIVE_WINDOW_POSES,
    arena_tag_scene,
    live_sim_camera,
    live_sim_tag_noise,
    run_live,
    simulated_camera,
)
from fgslam.live.steering import (
    LiveSettings,
    PoseTracker,
    WaypointFollower,
    polygon_waypoints,
    pose_error_m,
    read_waypoints,
    start_pose_facing,
    waypoint_wheel_speeds,
)
from fgslam.live.workers import (
    CameraWorker,
    ControlHold,
    Lockstep,
    SmootherWorker,
    release_hold,
    release_untaken,
)

__all__ = [
    "LiveSettings",
    "waypoint_wheel_speeds",
    "WaypointFollower",
    "PoseTracker",
    "Lockstep",
    "CameraWorker",
    "SmootherWorker",
    "LiveLoop",
    "LiveResult",
    "read_waypoints",
    "polygon_waypoints",
    "LatestFrame",
    "run_live",
    "LIVE_WINDOW_POSES",
    "simulated_camera",
    "start_pose_facing",
    "pose_error_m",
    "ControlHold",
    "release_hold",
    "release_untaken",
    "live_sim_camera",
    "live_sim_tag_noise",
    "arena_tag_scene",
    "LIVE_SIM_RANGE_SIGMA_PER_M2",
    "LIVE_SIM_SIGMA_BEARING_RAD",
    "LIVE_SIM_SIGMA_TAG_YAW_RAD",
    "LIVE_SIM_TAG_SIZE_M",
]

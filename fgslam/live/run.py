"""Assembling a live run: the simulated camera (a render of seed 004's arena tags) and its
measured noise, and :func:`run_live`, which wires the recorder, the workers and the loop."""

from __future__ import annotations

import time
from typing import Callable

import numpy as np

from fgslam.live.loop import LiveLoop, LiveResult
from fgslam.live.navigation import NavigatingController, ScanSlot, Sightings, navigating_camera
from fgslam.live.steering import LiveSettings, PoseTracker, WaypointFollower
from fgslam.live.workers import CameraWorker, Lockstep, SmootherWorker
from slamio.errors import FgslamError
from slamio.log import Odometry, Step, TruthLandmark
from slamio.log.mount import camera_mount_fields


#: What the AprilTag front-end reports from :func:`simulated_camera`'s frames (640×480, the
#: Kinect's intrinsics, rendered with pixel noise σ 2 grey levels and no supersampling):
#: σ_bearing constant, σ_range = c·r² (:class:`slamio.camera.detect.NoiseModel`). Measured by
#: ``scripts/measure_live_camera.py`` on frames rendered at poses drawn along the octagon and
#: square paths (RMS errors against the truth, outliers included), not on the runs it is
#: then checked with (docs/camera.md, "The simulated live camera").
#: Two draws of 400 frames (seeds 0 and 1): bearing 0.404 / 0.396 mrad, c 3.98 / 3.85 mm/m².
LIVE_SIM_SIGMA_BEARING_RAD = 4.0e-4
LIVE_SIM_RANGE_SIGMA_PER_M2 = 4.0e-3  # for LIVE_SIM_TAG_SIZE_M; c grows as 1/tag size
LIVE_SIM_TAG_SIZE_M = 0.16
#: The tag yaw's σ of those frames: RMS 0.070 / 0.121 rad over the same draws. IPPE's yaw of
#: a near-frontal tag is heavy-tailed (a flipped solution now and then), so this is a
#: second moment, not a Gaussian's width.
LIVE_SIM_SIGMA_TAG_YAW_RAD = 0.1


def live_sim_tag_noise(tag_size_m: float = LIVE_SIM_TAG_SIZE_M):
    """The :class:`slamio.camera.detect.NoiseModel` of :func:`simulated_camera`'s observations
    for tags of ``tag_size_m`` (a tag's apparent size, and so its range error, scales with it)."""
    from slamio.camera.detect import NoiseModel

    c = LIVE_SIM_RANGE_SIGMA_PER_M2 * LIVE_SIM_TAG_SIZE_M / tag_size_m
    return NoiseModel(0.0, 0.0, c, LIVE_SIM_SIGMA_BEARING_RAD, None, LIVE_SIM_SIGMA_TAG_YAW_RAD)


def arena_tag_scene(tag_size_m: float = 0.16):
    """Seed 004's eight arena tags as a render :class:`slamio.camera.render.Scene`."""
    from slamio.camera.render import Scene, TagSpec
    from slamio.sim import TAG_HEIGHT_M, arena_tags

    world = arena_tags()
    return Scene(tags=tuple(
        TagSpec(i, float(x), float(y), TAG_HEIGHT_M, float(yaw), size_m=tag_size_m)
        for i, ((x, y), yaw) in enumerate(zip(world.landmarks_xy, world.yaws_rad))
    ))


def live_sim_camera(mount_height_m: float = 0.2):
    """The simulated live camera: the Kinect's intrinsics on the robot's centre, looking ahead."""
    from slamio.camera.model import T_robot_camera_from_mount, kinect_v1_default

    return kinect_v1_default(T_robot_camera_from_mount(0.0, 0.0, mount_height_m))


def simulated_camera(sim, *, supersample: int = 1, pixel_noise: float = 2.0, seed: int = 0,
                     tag_size_m: float = 0.16, mount_height_m: float = 0.2, scene=None, camera=None,
                     depth_model: str = "ideal"):
    """The camera of a hardware-in-the-loop run: seed 004's eight arena tags (or ``scene``,
    e.g. the clutter room's, seen by ``camera``) rendered from the simulated Create's true
    pose at the instant each pose is made. Its observations carry the noise those frames
    have (:func:`live_sim_tag_noise`), so a replay of the log is consistent. Each frame has
    its registered depth (``depth_model``), from which a navigator's scan is made.

    Returns ``(grab_for, front_end, truth_landmarks)``: ``grab_for(index, odometry,
    true_pose=None)`` takes ``true_pose`` (the truth the live loop has just written) or
    snapshots the true pose now (in the control loop) and returns the grabber that renders
    it (run in the camera worker); ``truth_landmarks`` are the tags as log records.
    """
    from slamio.camera.detect import FrontEnd, FrontEndConfig
    from slamio.camera.render import render
    from slamio.camera.sources import Frame

    scene = arena_tag_scene(tag_size_m) if scene is None else scene
    camera = live_sim_camera(mount_height_m) if camera is None else camera
    front_end = FrontEnd(camera, FrontEndConfig(tag_size_m=tag_size_m, noise=live_sim_tag_noise(tag_size_m)))
    rng = np.random.default_rng(seed)  # used only in the camera worker

    def grab_for(index: int, odometry: Odometry, true_pose=None):
        pose = sim.true_pose if true_pose is None else true_pose  # now, or the truth the loop just wrote

        def grab():
            frame = render(camera, pose, scene, supersample=supersample, noise_sigma=pixel_noise, rng=rng,
                           depth_model=depth_model)
            return Frame(odometry.stamp_s, index, f"sim:{index}", frame.bgr, frame.depth_m)

        return grab

    truth_landmarks = [TruthLandmark(t.tag_id, t.x_m, t.y_m, t.z_m, t.yaw_rad) for t in scene.tags]
    return grab_for, front_end, truth_landmarks


#: The live smoother's sliding window (``Isam2Smoother(window_poses=...)``, fgslam/smoother/window.py):
#: iSAM2 holds between this many and twice this many of the newest poses, so a step costs the
#: same after an hour as after a minute. Measured on the live arena (seed 004's octagon and
#: tags, 40 laps, 13 208 poses, one BLAS thread; docs/performance.md): with every pose kept the
#: p99 step grew from 3.7 ms in the first quarter of the run to 27.9 ms in the last (the Create
#: streams every 15 ms); with 200 it stayed at 0.8–0.9 ms, the slowest step (a slide) 12 ms, the
#: whole run took 1.86 s instead of 8.79 s and the online ATE changed by +1.7 %. 200 poses at
#: the recorder's 0.1 s are 20 s of driving or more: at least one lap of the arena.
LIVE_WINDOW_POSES = 200


def unlabelled_colours(options) -> list[str]:
    """The names of the colour landmarks of ``options`` (a ``ColourOptions``) that have no id.
    The smoother pairs their observations against every pose of the run, which a sliding
    window cannot give it."""
    return [c.name for c in options.colours if c.landmark_id is None]


def unlabelled_landmarks(front_end) -> list[str]:
    """The landmarks ``front_end`` reports without an id (:func:`unlabelled_colours` of a
    colour front-end; AprilTags always carry theirs)."""
    config = getattr(front_end, "config", None)
    if config is None or config.kind != "colour":
        return []
    return unlabelled_colours(config.colour)


def _default_smoother(start_pose: tuple, front_end, window_poses: int | None):
    """:func:`run_live`'s smoother when the caller gives none: :class:`fgslam.smoother.Isam2Smoother`
    with its defaults and a sliding window of ``window_poses`` (none when ``front_end`` reports
    landmarks without an id: they are paired against every pose)."""
    from fgslam.smoother import Isam2Smoother
    from slamio.log import Header

    if unlabelled_landmarks(front_end):  # paired against every pose: no window
        window_poses = None
    header = Header(stamp_s=0.0, start_pose=start_pose, start_sigma=(1e-3, 1e-3, 1e-3),  # as the recorder's
                    robot={"name": "live"}, sensor={"kind": "live"}, noise={"odometry": {}, "observation": {}})
    return Isam2Smoother(header, window_poses=window_poses)


def _sensor_header(sensor: dict | None, observation_noise: dict | None, front_end) -> tuple[dict, dict | None]:
    """The log header's ``sensor`` and ``noise.observation`` of a live run: the caller's, or
    what the camera front-end (None: no camera) says — the mount each detection was placed
    from, and the σ it gives each observation (each record carries its own)."""
    sensor = sensor or {"kind": "range-bearing", "landmark_kind": "apriltag" if front_end is not None else "none",
                        "source": "fgslam live"}
    mounted = getattr(getattr(front_end, "camera", None), "T_robot_camera", None)
    if mounted is not None:
        sensor = {**sensor, **camera_mount_fields(mounted)}
    if observation_noise is None and getattr(front_end, "noise", None) is not None:
        observation_noise = {**front_end.noise.describe(), "source": "the camera front-end's noise model"}
    return sensor, observation_noise


def run_live(link, out_path: str, waypoints, *, start_pose, grab_for=None, front_end=None,
             settings: LiveSettings = LiveSettings(), smoother=None, truth=None, truth_landmarks=(),
             clock: Callable[[], float] = time.monotonic, sensor: dict | None = None,
             observation_noise: dict | None = None, odometry_noise=None, on_step=None,
             lockstep: Lockstep | None = None, window_poses: int | None = LIVE_WINDOW_POSES,
             overwrite: bool = False, signals=None, navigator=None, scan_camera=None,
             duration_s: float | None = None, until_landmarks: int | None = None) -> LiveResult:
    """Drive ``waypoints`` on the robot behind ``link`` with iSAM2 in the loop; log to
    ``out_path``. ``grab_for``/``front_end`` give the camera (None: odometry only);
    ``smoother`` defaults to :class:`fgslam.smoother.Isam2Smoother` with its defaults and a
    sliding window of ``window_poses`` (:data:`LIVE_WINDOW_POSES`; None keeps every pose in
    iSAM2, as ``fgslam run`` does, and so does a front-end with landmarks without an id,
    :func:`unlabelled_landmarks`; the final estimate is the whole graph's either way).
    ``on_step(index, smoother, latency_s, loop)`` is called in the smoother worker after
    each pose (the CLI's status line and map; ``loop`` is the :class:`LiveLoop` with its
    frame counts). ``odometry_noise`` (an :class:`slamio.create.odometry.OdometryNoise`) is
    the odometry noise the log states; None: the recorder's nominal model.
    ``observation_noise`` is the header's observation-model entry; None: the front-end's
    noise model (every observation record carries its own σ either way).

    ``lockstep`` (simulation only, :class:`Lockstep`) gives every frame and smoother step a
    fixed budget of robot time, so how fast this machine renders, detects and smooths
    changes the run's wall time, never what happens in robot time. On a real robot time
    does not stop: leave it None.

    ``overwrite`` and ``signals`` go to :func:`slamio.create.record.record`: the log replaces
    an existing ``out_path`` only once the robot has answered, and the terminating signals
    stop the robot (the caller installs ``signals``; None: the recording installs its own).

    ``navigator`` (a :mod:`fgslam.navigate` policy) drives instead of ``waypoints``: it steers
    by the obstacle scan of each frame's depth (``scan_camera``: the depth's intrinsics and
    mount, :mod:`fgslam.live.navigation`); a bump stops the wheels, is logged as an event and
    the navigator backs off, the run goes on. ``duration_s`` (robot seconds) and
    ``until_landmarks`` (that many landmarks seen) end the run normally."""
    from slamio.create.record import record
    from slamio.create.record_settings import RecorderSettings

    start_pose = tuple(float(v) for v in start_pose)
    if lockstep is not None and not lockstep.frame_s < settings.frame_timeout_s:
        raise FgslamError(f"lockstep frame budget {lockstep.frame_s} s must be below frame_timeout_s "
                          f"{settings.frame_timeout_s} s")
    if smoother is None:
        smoother = _default_smoother(start_pose, front_end, window_poses)
    tracker = PoseTracker(start_pose)
    scans, sightings = ScanSlot(), Sightings()
    camera, grab_for = _camera(front_end, grab_for, lockstep, tracker, (scans, scan_camera) if navigator else None)

    def step_hook(index, smoother_, latency):
        if navigator is not None and index % 10 == 0:  # the map the navigator revisits, once a second
            sightings.mapped(smoother_.landmarks())
        if on_step is not None:
            on_step(index, smoother_, latency, loop)

    worker = SmootherWorker(smoother, tracker, step_hook, lockstep=lockstep)
    loop = LiveLoop(tracker, camera, worker, grab_for, settings, truth, truth_landmarks, lockstep=lockstep,
                    until=sightings.until(until_landmarks), on_observations=sightings.seen)
    worker.submit(Step(0, 0.0, None, (), None))  # pose 0: the start pose (lockstep: the clock stands already)
    if navigator is not None:
        follower = NavigatingController(navigator, tracker.current, scans, sightings, accel_m_s2=settings.accel_m_s2,
                                        on_advance=tracker.advance)
    else:
        follower = WaypointFollower(waypoints, tracker.current, settings, on_advance=tracker.advance)
    loop.controller = follower  # the status line shows a navigator's state
    recorder = RecorderSettings(speed_m_s=settings.speed_m_s, turn_rate_rad_s=settings.turn_rate_rad_s,
                                accel_m_s2=settings.accel_m_s2, record_period_s=settings.record_period_s,
                                command_timeout_s=settings.command_timeout_s, data_timeout_s=settings.data_timeout_s,
                                duration_s=duration_s, bump_ends_run=navigator is None)
    sensor, observation_noise = _sensor_header(sensor, observation_noise, front_end if camera is not None else None)
    try:
        result = record(link, out_path, follower, settings=recorder, clock=clock, hooks=loop,
                        start_pose=start_pose, sensor=sensor, observation_noise=observation_noise,
                        noise=odometry_noise, overwrite=overwrite, signals=signals,
                        source=_source(waypoints, navigator))
    finally:
        loop.close()
    if worker.error is not None:  # after the last record: the recorder did not see it
        raise FgslamError(f"live loop: {type(worker.error).__name__}: {worker.error}") from worker.error
    smoother.finish()
    return _live_result(result, smoother, loop, worker, camera, follower)


def _camera(front_end, grab_for, lockstep, tracker: PoseTracker, scanning):
    """The camera worker of a live run and the grabber the loop asks frames from (None:
    no camera). ``scanning`` = (a :class:`ScanSlot`, the depth's camera) also makes each
    frame's obstacle scan for a navigator."""
    if grab_for is None or front_end is None:
        return None, grab_for
    if scanning is None:
        def process(frame):
            return front_end.process(frame).observations
    else:
        grab_for, process = navigating_camera(front_end, grab_for, tracker.current, *scanning)
    return CameraWorker(process, lockstep=lockstep), grab_for


def _live_result(result, smoother, loop: LiveLoop, worker: SmootherWorker, camera, follower) -> LiveResult:
    return LiveResult(
        record=result,
        final_pose=tuple(float(v) for v in smoother.current_pose()),  # type: ignore[arg-type]
        poses=loop.poses,
        frames_requested=loop.frames_requested,
        frames_used=loop.frames_used,
        frames_skipped=loop.frames_skipped,
        frames_dropped=loop.frames_dropped,
        observations=loop.observations,
        latencies_s=np.array(worker.latencies_s),
        frame_seconds=np.array(camera.frame_seconds if camera else []),
        landmarks=dict(smoother.landmarks()),
        navigator_step_s=np.array(getattr(follower, "step_seconds", [])),
    )


def _source(waypoints, navigator) -> dict:
    """The header's ``source`` of a live run: the waypoints driven, or the navigator that drove."""
    if navigator is not None:
        return {"generator": "fgslam.live", "navigator": navigator.name}
    return {"generator": "fgslam.live", "waypoints": np.asarray(waypoints).tolist()}

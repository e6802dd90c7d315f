"""``fgslam live``: iSAM2 in the loop on the robot (or the simulated one), everything recorded.

Exit status (:mod:`fgslam.cli.robot_end`): 0 when the path was driven to its end and the
robot confirmed its stop, 2 when the robot was stopped early (bump, wheel drop, watchdog, no
data, lost serial link, a full disk; the log is kept and the reason printed), 3 when the stop
was sent but not confirmed, 128 + N on signal N (SIGHUP, SIGINT, SIGQUIT, SIGTERM), 1 on a
user error.
"""

from __future__ import annotations

import argparse
import math
import sys
import threading
import time
from pathlib import Path

import numpy as np

import fgslam.cli.live_navigate as live_navigate
from fgslam.cli.common import add_overwrite_option, add_verb, check_new_file, check_number
from fgslam.cli.progress import Progress
from fgslam.cli.robot_end import report_end, robot_session, say
from fgslam.cli.verbs import help_of
from slamio.errors import FgslamError


DESCRIPTION = """\
Drive an iRobot Create along waypoints, closing the loop on the iSAM2 pose, while the camera
front-end turns frames into landmark observations and iSAM2 smooths them; record every input
to a run log as it arrives, so `fgslam run LOG` replays the run with every estimator.

paths: square or octagon (seed 004's, in its 10 ft arena: --side across flats, default
1.83 m, centred at --centre, default 1.524,1.524), or a file of 'x_m, y_m' lines. The robot
starts on the path's last corner facing the first (or at --start-pose): place it there.

A status line on stderr (on a terminal redrawn twice a second, else a line every 5 s) shows
the pose with its standard deviations (iSAM2's marginal),
the landmarks, iSAM2 latency and frames; --map-png
rewrites a picture of the map every 2 s. Stop with Ctrl-C: the wheels stop first, then the
log is closed. Bumps, wheel drops, a lost serial link, a hung loop, a full disk, SIGHUP (the
SSH session dropped), SIGQUIT and SIGTERM stop the robot too, and the stop counts as done
only when the robot reads back stopped; a guardian process stops it if this program is
killed outright. Without --camera on a real robot the run is odometry only.

--port sim runs it all in simulation: the simulated Create on a pseudo-terminal and a
camera rendered from its true pose (the hardware-in-the-loop test); the log then has the
ground truth too.
"""


def _floats(count: int):
    def parse(text: str):
        try:
            values = tuple(float(v) for v in text.split(","))
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {count} comma-separated numbers, got {text!r}") from None
        if len(values) != count:
            raise argparse.ArgumentTypeError(f"expected {count} comma-separated numbers, got {text!r}")
        return values

    return parse


def add_parser(verbs) -> argparse.ArgumentParser:
    from slamio.sim_worlds import ARENA_PATH_WIDTH_M, ARENA_SIDE_M

    live = add_verb(verbs, "live", description=DESCRIPTION,
                    help=help_of("live"))
    live.add_argument("--port", required=True, help="serial port (e.g. /dev/ttyUSB0) or 'sim'")
    live.add_argument("--model", choices=("create1", "create2"), default="create2")
    live.add_argument("--path", default=None, help="square, octagon or a waypoint file (default octagon)")
    live.add_argument("--laps", type=int, default=1)
    live.add_argument("--side", type=float, default=ARENA_PATH_WIDTH_M, metavar="M",
                      help=f"square/octagon width across flats (default {ARENA_PATH_WIDTH_M} m)")
    live.add_argument("--centre", type=_floats(2), default=(0.5 * ARENA_SIDE_M, 0.5 * ARENA_SIDE_M), metavar="X,Y")
    live.add_argument("--start-pose", type=_floats(3), default=None, metavar="X,Y,THETA",
                      help="where the robot starts in the map frame (default: last corner, facing the first)")
    live.add_argument("--speed", type=float, default=0.2, metavar="M_S", help="cruising speed (default 0.2)")
    live.add_argument("--camera", default=None, metavar="CAM.yaml", help="camera file of a real camera: a ROS camera_info YAML "
                           "or a Kalibr cameras.yaml")
    live.add_argument("--camera-name", default=None, metavar="NAME",
                      help="the camera of a Kalibr file holding several (cam0, cam1, ...)")
    live.add_argument("--frames", default=None,
                      help="frame source: camera:N or kinect:N (default camera:0; with --port sim the camera is "
                           "simulated)")
    live.add_argument("--tag-size", type=float, default=0.16, metavar="M", help="AprilTag size (default 0.16 m)")
    live.add_argument("--kind", choices=("apriltag", "colour"), default="apriltag",
                      help="landmarks: AprilTags (default) or Kinect colour landmarks (with --port sim: seed 000's "
                      "cylinders in three corners of the arena)")
    live.add_argument("--landmarks", default=None, metavar="FILE",
                      help="colour: the landmark file (default seed 000's red/green/blue cylinders)")
    live.add_argument("--out", required=True, metavar="LOG", help="run log to write; an existing one is kept")
    add_overwrite_option(live, "an existing LOG and --map-png picture")
    live.add_argument("--map-png", default=None, metavar="PNG",
                      help="rewrite a map picture here every 2 s (in an existing folder; an existing file is kept "
                      "unless --overwrite)")
    live.add_argument("--window", type=int, default=None, metavar="N",
                      help="iSAM2 keeps the newest N to 2N poses and marginalises the older ones, so a step "
                      "costs the same however long the run (default 200; 0 keeps every pose; colour landmarks "
                      "without ids need 0, and get it by default). The final map solves every pose either way")
    live.add_argument("--baud", type=int, default=None)
    live.add_argument("--watchdog", type=float, default=0.5, metavar="S",
                      help="stop the robot when the control loop sends no command, or no valid sensor reading "
                           "arrives, for S seconds of wall time (default 0.5; more for a slow computer)")
    live.add_argument("--sim-time-scale", type=float, default=1.0, help="simulation: robot seconds per wall second")
    live.add_argument("--sim-seed", type=int, default=1)
    live.add_argument("--sim-unplug-after", type=float, default=None, metavar="S",
                      help="simulation: pull the simulated cable after S robot seconds (fault test)")
    live_navigate.add_options(live)
    live.set_defaults(func=cmd_live)
    return live


def _waypoints(args) -> np.ndarray:
    from fgslam.live import polygon_waypoints, read_waypoints

    if args.path in ("square", "octagon"):
        return polygon_waypoints(4 if args.path == "square" else 8, args.side, tuple(args.centre), args.laps)
    return np.vstack([read_waypoints(args.path)] * max(1, args.laps))


def _check_inside_arena(waypoints: np.ndarray, start_pose, path: str, *, given_start: bool) -> None:
    """With --port sim: the start and every waypoint inside the simulated arena with room for the
    robot (its disc clear of the walls), else one line before it starts, not a bump stop later."""
    from slamio.create.sim import ARENA_M, ROBOT_RADIUS_M

    width, height = ARENA_M
    margin = ROBOT_RADIUS_M
    start = "--start-pose" if given_start else "the start pose (the path's last waypoint: --start-pose sets another)"
    points = [(start, start_pose[:2])] + [(f"waypoint {i + 1} of --path {path}", p[:2])
                                                   for i, p in enumerate(waypoints)]
    for what, (x, y) in points:
        if not (margin <= x <= width - margin and margin <= y <= height - margin):
            raise FgslamError(
                f"{what} ({x:.3f}, {y:.3f}) m is outside the simulated arena (x and y within {margin:.2f} .. "
                f"{width - margin:.2f} m: the {width:.3f} m square less the robot's {margin:.2f} m radius); the robot "
                "would drive into a wall")


#: Where a navigator starts in seed 004's arena when --start-pose is not given: its centre, facing +x.
DEFAULT_NAVIGATE_START = (1.524, 1.524, 0.0)

#: The Create's top wheel speed (slamio.create.record refuses more, but only once the robot is up).
MAX_SPEED_M_S = 0.5


def _check_options(args: argparse.Namespace) -> None:
    """Every option, before the port is opened and the robot moves: a bad value is one line
    naming the option, never a stop after pose 0 (or a robot driving something else)."""
    path_given = args.path is not None
    args.path = args.path or "octagon"
    live_navigate.check_options(args, path_given)
    if args.laps < 1:
        raise FgslamError(f"--laps must be >= 1 (how many times the path is driven); got {args.laps}")
    if args.port == "sim" and (args.camera is not None or args.frames is not None):
        given = "--camera" if args.camera is not None else "--frames"
        raise FgslamError(f"{given} is for a real robot's camera: with --port sim the frames are rendered from the "
                          "simulated robot's true pose by a simulated camera; leave --camera and --frames out")
    check_number("--side", args.side, above=0, what="metres across flats of the square or octagon, e.g. 1.83")
    check_number("--centre", tuple(args.centre), what="the path's centre X,Y in metres, e.g. 1.524,1.524")
    if args.start_pose is not None:
        check_number("--start-pose", tuple(args.start_pose), what="X,Y in metres and THETA in radians")
    check_number("--speed", args.speed, above=0, at_most=MAX_SPEED_M_S,
                  what=f"m/s; the Create drives at most {MAX_SPEED_M_S:g} m/s, e.g. 0.2")
    check_number("--watchdog", args.watchdog, above=0, what="seconds of wall time, e.g. 0.5")
    check_number("--tag-size", args.tag_size, above=0, what="metres: the side of the tag's black square, e.g. 0.16")
    check_number("--sim-time-scale", args.sim_time_scale, above=0, what="robot seconds per wall second, e.g. 1 or 10")
    if args.sim_seed < 0:
        raise FgslamError(f"--sim-seed must be >= 0; got {args.sim_seed}")
    if args.sim_unplug_after is not None:
        check_number("--sim-unplug-after", args.sim_unplug_after, at_least=0, what="robot seconds")
    if args.baud is not None and args.baud < 1:
        raise FgslamError(f"--baud must be a positive number of bits per second (e.g. 57600 or 115200); "
                          f"got {args.baud}")
    if args.landmarks and args.kind != "colour":
        raise FgslamError("--landmarks describes colour landmarks: add --kind colour")
    if args.window is not None and (args.window < 0 or args.window == 1):
        raise FgslamError(f"--window must be 0 (keep every pose) or at least 2 poses, e.g. 200; got {args.window}")
    check_new_file(args.out, overwrite=args.overwrite)  # an existing log is kept
    if args.map_png:
        _check_map_png(Path(args.map_png), Path(args.out), args.overwrite)


def _check_map_png(png: Path, out: Path, overwrite: bool) -> None:
    """--map-png: a new (or, with --overwrite, an existing) file in a folder that can be written
    (made before the robot moves, as the log's is), not the log. The picture is rewritten during
    the run, where a failure would stop it."""
    check_new_file(png, overwrite=overwrite, option="--map-png", example="map.png")
    if png.resolve() == out.resolve():
        raise FgslamError(f"--map-png {png} is the run log (--out); give the picture another name, e.g. map.png")


def cmd_live(args: argparse.Namespace) -> int:
    from fgslam.live import LiveSettings, start_pose_facing

    _check_options(args)  # before the port is opened and the robot moves
    for path in (args.out, args.map_png):  # their folders, as record makes its own: nothing fails mid-run
        if path:
            Path(path).parent.mkdir(parents=True, exist_ok=True)
    window_poses = _window_poses(args)
    sensor = ({"kind": "range-bearing", "landmark_kind": "coloured-cylinder", "source": "fgslam live"}
              if args.kind == "colour" else None)
    world = live_navigate.clutter_world(args) if args.world == "clutter" else None
    waypoints = _waypoints(args) if args.navigate is None else np.zeros((0, 2))
    if world is not None:
        start_pose = live_navigate.start_pose_of(world, args)
        live_navigate.check_inside_room(world, waypoints, start_pose, given_start=args.start_pose is not None)
    else:
        start_pose = (tuple(args.start_pose) if args.start_pose else
                      start_pose_facing(waypoints) if len(waypoints) else DEFAULT_NAVIGATE_START)
        if args.port == "sim":
            _check_inside_arena(waypoints, start_pose, args.path, given_start=args.start_pose is not None)
    watchdog = args.watchdog
    if args.port == "sim" and args.navigate is not None:  # lockstep: the robot streams nothing while its clock stands
        watchdog = max(watchdog, live_navigate.LOCKSTEP_WATCHDOG_S)
    settings = LiveSettings(speed_m_s=args.speed, command_timeout_s=watchdog, data_timeout_s=watchdog)
    status = Progress(unit="poses")
    last_map = [0.0]

    worst_ms = [0.0]

    def on_step(index, smoother, latency_s, loop):
        worst_ms[0] = max(worst_ms[0], 1e3 * latency_s)

        def text():  # the marginal and the map only when a line is shown
            x, y, th = smoother.current_pose()
            sigma = np.sqrt(np.diag(smoother.current_covariance()))  # the published covariance, as 1-sigma
            return (f"pose {index:5d}  x {x:6.3f} y {y:6.3f} m ±{max(sigma[:2]):.3f}  θ {math.degrees(th):6.1f}° "
                    f"±{math.degrees(sigma[2]):.1f}  landmarks {len(smoother.landmarks()):2d}  "
                    f"iSAM2 {1e3 * latency_s:5.2f} ms (max {worst_ms[0]:5.2f})  "
                    f"frames {loop.frames_used} used, {loop.frames_skipped + loop.frames_dropped} dropped"
                    + live_navigate.status_text(loop))

        status.status(index + 1, text)
        if args.map_png and time.monotonic() - last_map[0] > 2.0:
            from fgslam.report import plot_live_map

            last_map[0] = time.monotonic()
            plot_live_map(args.map_png, smoother.trajectory(), smoother.landmarks(), waypoints)

    with robot_session((args.out, "--out"), (args.map_png, "--map-png")) as signals:  # one writer per log; every terminating signal stops the robot
        check_new_file(args.out, overwrite=args.overwrite)  # again, under the lock
        result, sim_truth = _drive(args, waypoints, start_pose, settings, status, on_step, sensor, window_poses,
                                   signals, world)
        with signals.held(raise_after=False):  # the robot is stopped: what is left is to say so
            return _report(args, result, sim_truth)


def _drive(args, waypoints, start_pose, settings, status, on_step, sensor, window_poses, signals, world):
    """Start the simulator (--port sim) or the camera, open the link, run the live loop.
    Returns the :class:`LiveResult` and the simulator's true end pose (None: a real robot)."""
    from fgslam.live import Lockstep, run_live
    from slamio.create.link import CreateLink

    sim = link = None
    true_pose = None
    unplug_timer = None
    odometry_noise = None  # a real robot: the recorder's nominal model
    lockstep = scan_camera = navigator = None
    try:
        if args.port == "sim":
            from slamio.create.sim import SimulatedCreate

            room = live_navigate.clutter_sim_kwargs(world) if world is not None else {}
            sim = SimulatedCreate(args.model, seed=args.sim_seed, time_scale=args.sim_time_scale,
                                  start_pose=start_pose, **room).start()
            grab_for, front_end, truth_landmarks, scan_camera = live_navigate.sim_frames(
                world, args, sim, _colour_options(args) if args.kind == "colour" else None)
            if args.navigate is not None:  # the same run on any machine: frames and steps take fixed robot time
                lockstep = Lockstep(sim)
            port, clock, truth = sim.port, sim.clock, (lambda: sim.true_pose)
            odometry_noise = sim.odometry_noise  # the log states what the simulated encoders do
            if args.sim_unplug_after is not None:
                def unplug_when_due():
                    while sim.clock() < args.sim_unplug_after and sim.plugged:
                        time.sleep(0.01)
                    sim.unplug()

                unplug_timer = threading.Thread(target=unplug_when_due, daemon=True)
                unplug_timer.start()
        else:
            grab_for, front_end = _real_camera(args)
            scan_camera = getattr(front_end, "camera", None)
            port, clock, truth, truth_landmarks = args.port, time.monotonic, None, ()
        if args.navigate is not None:
            from fgslam.navigate import make_navigator

            navigator = make_navigator(args.navigate, seed=args.sim_seed)
        link = CreateLink(port, args.model, baud=args.baud)
        link.open()  # a port that does not open is a user error (exit 1), before the log exists
        if sim is not None:  # the simulator waits for what this process has read (slamio.create.sim)
            sim.unread.host_bytes_read = lambda: link.bytes_read
        result = run_live(link, args.out, waypoints, start_pose=start_pose, grab_for=grab_for, front_end=front_end,
                          settings=settings, truth=truth, truth_landmarks=truth_landmarks, clock=clock,
                          odometry_noise=odometry_noise, on_step=on_step, sensor=sensor, window_poses=window_poses,
                          overwrite=args.overwrite, signals=signals, lockstep=lockstep, navigator=navigator,
                          scan_camera=scan_camera, duration_s=args.duration, until_landmarks=args.until_landmarks)
    finally:
        with signals.held(raise_after=False):
            status.close()
            if link is not None:
                link.close()
            if sim is not None:
                true_pose = sim.true_pose
                sim.close()
    return result, true_pose


def _report(args, result, true_pose) -> int:
    """The run's summary on stdout, how it ended on stderr; the exit status."""
    lat = 1e3 * result.latencies_s
    if result.record.log_placed:
        say(f"wrote {args.out}: {result.poses} poses, {result.observations} observations from "
            f"{result.frames_used} of {result.frames_requested} frames ({result.frames_skipped} skipped: camera busy, "
            f"{result.frames_dropped} dropped: too late)", sys.stdout)
    if len(lat):
        say(f"iSAM2 step latency: median {np.median(lat):.2f} ms, p99 {np.percentile(lat, 99):.2f} ms, "
            f"max {lat.max():.2f} ms", sys.stdout)
    for line in live_navigate.report_lines(result):
        say(line, sys.stdout)
    x, y, th = result.final_pose
    say(f"final iSAM2 pose: x {x:.3f} m, y {y:.3f} m, θ {math.degrees(th):.1f}°; "
        f"{len(result.landmarks)} landmarks", sys.stdout)
    if true_pose is not None:
        from fgslam.live import pose_error_m

        say(f"simulator's true pose: x {true_pose[0]:.3f} m, y {true_pose[1]:.3f} m, "
            f"θ {math.degrees(true_pose[2]):.1f}°; position error {pose_error_m(result.final_pose, true_pose):.4f} m",
            sys.stdout)
    return report_end("live", result.record, args.out)


def _real_camera(args):
    """(grab_for, front_end) for a real camera: the newest frame of a background reader."""
    if args.camera is None:
        if args.frames is not None:
            raise FgslamError(f"--frames {args.frames} needs --camera CAM.yaml, the camera's calibration "
                              "(fgslam calibrate-camera writes one)")
        say("fgslam live: no --camera: odometry only (iSAM2 smooths the odometry; no landmarks). Give --camera "
            "CAM.yaml to map landmarks")
        return None, None
    from fgslam.live import LatestFrame
    from slamio.camera.detect import FrontEnd, FrontEndConfig
    from slamio.camera.model import load_camera
    from slamio.camera.sources import kinect_frames, video_frames

    camera = load_camera(args.camera, args.camera_name)
    frames_source = args.frames or "camera:0"
    kind, _, number = frames_source.partition(":")
    if kind not in ("camera", "kinect") or not number.isdigit():
        raise FgslamError(f"--frames must be camera:N or kinect:N, got {frames_source!r}")
    frames = video_frames(int(number)) if kind == "camera" else kinect_frames(int(number))
    latest = LatestFrame(frames)
    if args.kind == "colour":
        from fgslam.live_colour import colour_front_end

        return latest.grab_for, colour_front_end(camera, _colour_options(args))
    return latest.grab_for, FrontEnd(camera, FrontEndConfig(tag_size_m=args.tag_size))


def _window_poses(args) -> int | None:
    """--window: the sliding window of the live smoother, or None to keep every pose. Colour
    landmarks without an id are paired by the smoother against every pose of the run, which a
    window cannot give (:func:`fgslam.live.run.unlabelled_landmarks`): by default they turn it
    off, and an explicit --window is refused."""
    from fgslam.live import LIVE_WINDOW_POSES
    from fgslam.live.run import unlabelled_colours

    unlabelled = unlabelled_colours(_colour_options(args)) if args.kind == "colour" else []
    if args.window == 0 or (args.window is None and unlabelled):
        return None
    if unlabelled:
        raise FgslamError(f"--window {args.window}: the colour landmarks {', '.join(unlabelled)} have no id, and "
                          "pairing them reads every pose of the run; give them ids in the landmark file or "
                          "run with --window 0")
    return LIVE_WINDOW_POSES if args.window is None else args.window


def _colour_options(args):
    from slamio.camera.colour import ColourOptions
    from slamio.camera.landmark_file import load_landmarks

    return load_landmarks(args.landmarks) if args.landmarks else ColourOptions()

"""``fgslam live``'s navigation and world options: ``--navigate NAME`` (a navigator drives
instead of ``--path``), ``--world arena|clutter`` (the simulated world of ``--port sim``),
``--duration S`` and ``--until-landmarks N`` (normal ends of a run).

Kept apart from :mod:`fgslam.cli.live` so that file stays about the path and the robot."""

from __future__ import annotations

import argparse

from slamio.errors import FgslamError

WORLDS = ("arena", "clutter")

#: The watchdog (wall seconds) of a simulated navigated run. It runs in lockstep: the
#: simulated clock stands while a frame is rendered, detected and scanned, and the robot
#: streams nothing meanwhile — but neither does it move, so a busy machine's long frame is
#: no hazard (fgslam.live.Lockstep). A real robot keeps --watchdog.
LOCKSTEP_WATCHDOG_S = 30.0


#: The names of fgslam.navigate.NAVIGATORS (a test keeps them equal): the parser needs the
#: names only, and importing the navigators (scipy.ndimage) would cost every verb ~0.2 s.
NAVIGATORS = ("vfh-s000", "vfh", "explore-s001", "explore")


def add_options(live: argparse.ArgumentParser) -> None:
    live.add_argument("--navigate", default=None, choices=NAVIGATORS, metavar="NAME",
                      help="let a navigator drive instead of --path, steering by the obstacle scan of the camera's "
                      f"depth: {', '.join(NAVIGATORS)} (docs/navigate.md). Bumps stop the wheels, are logged and "
                      "counted, and the navigator backs off; the run goes on")
    live.add_argument("--duration", type=float, default=None, metavar="S",
                      help="end the run normally after S seconds of robot time (exit 0)")
    live.add_argument("--until-landmarks", type=int, default=None, metavar="N",
                      help="end the run normally once N different landmarks have been seen")
    live.add_argument("--world", choices=WORLDS, default=None,
                      help="with --port sim: seed 004's 10 ft arena (the default for --path) or a cluttered 6 x 6 m "
                      "room of boxes, pillars, seed 000's colour cylinders and AprilTags drawn from --sim-seed (the "
                      "default and the only world for --navigate: the arena's walls are not drawn; docs/clutter.md)")


def check_options(args: argparse.Namespace, path_given: bool) -> None:
    """The navigation options, before the robot moves."""
    from fgslam.cli.common import check_number

    if args.duration is not None:
        check_number("--duration", args.duration, above=0, what="seconds of robot time, e.g. 300")
    if args.until_landmarks is not None and args.until_landmarks < 1:
        raise FgslamError(f"--until-landmarks must be >= 1; got {args.until_landmarks}")
    if args.navigate is not None and path_given:
        raise FgslamError(f"--navigate {args.navigate} drives by itself: leave out --path (and --laps, --side, "
                          "--centre), or leave out --navigate to drive the path")
    if args.world is None:
        args.world = "clutter" if args.navigate is not None and args.port == "sim" else "arena"
    if args.navigate is not None and args.port == "sim" and args.world != "clutter":
        raise FgslamError("--navigate with --port sim needs --world clutter: the arena's walls are not in the simulated "
                          "camera's depth, so a navigator could not see them")
    if args.world != "arena" and args.port != "sim":
        raise FgslamError(f"--world {args.world} is a simulated world: it needs --port sim")
    if args.world == "clutter" and args.navigate is None and not path_given:
        raise FgslamError("--world clutter: the square and octagon paths run into its boxes; give --navigate NAME "
                          "(e.g. vfh or explore) or a --path file of waypoints through the room")
    if args.navigate is not None and args.port != "sim":
        frames = args.frames or "camera:0"
        if not frames.startswith("kinect:"):
            raise FgslamError(f"--navigate needs depth to see obstacles: give --frames kinect:N (a Kinect's registered "
                              f"depth), not {frames}")


def clutter_world(args):
    """The clutter room of ``--sim-seed``."""
    from slamio.clutter import clutter_world as draw

    return draw(args.sim_seed)


def check_inside_room(world, waypoints, start_pose, *, given_start: bool) -> None:
    """With --world clutter: the start pose and any waypoints clear of the room's obstacles
    (the robot's disc fits), else one line naming the point before the robot moves."""
    from slamio.create.sim import ROBOT_RADIUS_M
    from slamio.obstacles import clearance_m

    start = "--start-pose" if given_start else "the room's start pose"
    points = [(start, start_pose[:2])] + [(f"waypoint {i + 1} of --path", p[:2]) for i, p in enumerate(waypoints)]
    for what, (x, y) in points:
        room_w, room_h = world.room_m
        inside = 0 < x < room_w and 0 < y < room_h
        clear = clearance_m(world.obstacles, (x, y))
        if not inside or clear < ROBOT_RADIUS_M:
            raise FgslamError(f"{what} ({x:.3f}, {y:.3f}) m is not clear in the clutter room of --sim-seed: the "
                              f"nearest obstacle is {max(clear, 0.0):.3f} m away, the robot's radius "
                              f"{ROBOT_RADIUS_M:.2f} m (the room is {room_w:g} x {room_h:g} m, corner at the origin)")


def start_pose_of(world, args) -> tuple[float, float, float]:
    return tuple(args.start_pose) if args.start_pose else tuple(float(v) for v in world.start_pose)


def status_text(loop) -> str:
    """The navigator's part of the status line: its state and the bumps so far."""
    controller = getattr(loop, "controller", None)
    state = getattr(controller, "state", None)
    return f"  nav {state}" if state is not None else ""


def report_lines(result) -> list[str]:
    """What a navigated run adds to the summary: bumps and the navigator's cost per step."""
    lines = []
    bumps = getattr(result.record, "bumps", 0)
    steps = result.navigator_step_s
    if len(steps):
        import numpy as np

        lines.append(f"navigator: {len(steps)} steps, median {1e6 * np.median(steps):.0f} µs, p99 "
                     f"{1e6 * np.percentile(steps, 99):.0f} µs, max {1e6 * steps.max():.0f} µs; "
                     f"{bumps} bump{'s' if bumps != 1 else ''} (the run went on)")
    elif bumps:
        lines.append(f"{bumps} bumps")
    return lines


def sim_frames(world, args, sim, colour_options):
    """``(grab_for, front_end, truth_landmarks, scan_camera)`` of the simulated camera in the
    chosen world: the arena's tag camera, or in the clutter room a Kinect 0.13 m ahead and
    0.30 m up (57°, its quantised depth) seeing the room's tags or colour cylinders."""
    from fgslam.live import simulated_camera
    from slamio.camera.depth_scan import kinect_scan_camera

    if world is None:  # the arena: no scan (a navigator needs the clutter room)
        if args.kind == "colour":
            from fgslam.live_colour import simulated_kinect

            return (*simulated_kinect(sim, colour_options, seed=args.sim_seed), None)
        return (*simulated_camera(sim, seed=args.sim_seed, tag_size_m=args.tag_size), None)
    camera = kinect_scan_camera()
    if args.kind == "colour":
        from fgslam.live_colour import simulated_kinect

        grab_for, front_end, truth = simulated_kinect(sim, colour_options, seed=args.sim_seed,
                                                      scene=world.scene(), camera=camera)
        return grab_for, front_end, truth, camera
    sizes = {round(t.size_m, 6) for t in world.tags}
    tag_size = sizes.pop() if len(sizes) == 1 else args.tag_size
    grab_for, front_end, truth = simulated_camera(sim, seed=args.sim_seed, tag_size_m=tag_size, scene=world.scene(),
                                                  camera=camera, depth_model="kinect")
    return grab_for, front_end, truth, camera


def clutter_sim_kwargs(world) -> dict:
    """The simulated Create's world: the room's walls and objects instead of the arena's walls."""
    return {"arena_m": None, "obstacles": world.obstacles}


"""``fgslam record``: drive an iRobot Create (or the simulated one) and record its odometry.

Exit status (:mod:`fgslam.cli.robot_end`): 0 when the path was driven to the end (or teleop
quit) and the robot confirmed its stop; 2 when the robot was stopped early (bump, wheel
drop, watchdog, no data, serial error, time limit, a full disk; the log is kept and the
reason printed); 3 when the stop was sent but the robot did not confirm it; 128 + N on
signal N (SIGHUP 129, SIGINT 130, SIGQUIT 131, SIGTERM 143); 1 on a user error (bad option,
port that does not open, an existing --out without --overwrite, another fgslam writing it).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from fgslam.cli.common import (add_overwrite_option, add_verb, check_new_file, check_number, command_line,
                               stale_status_files, status_path)
from fgslam.cli.robot_end import EXIT_STOPPED_EARLY, report_end, robot_session, say  # noqa: F401 (fgslam.record_cli)
from fgslam.cli.verbs import help_of
from slamio.errors import FgslamError

EXIT_INTERRUPTED = 130  # SIGINT; any signal N exits 128 + N

RECORD_DESCRIPTION = """\
Drive an iRobot Create along a scripted path (or from the keyboard) and write its odometry
to a run log, one record every 0.1 s, flushed as written: a recorder that is killed leaves
every record but at most the last.

The robot stops (and the log is kept) on a bump, a wheel drop, when it leaves Safe mode,
when the host stops sending commands for 0.5 s (watchdog), when no valid sensor data comes
for 0.5 s, when the serial port fails, when the disk is full, and on SIGHUP (the SSH
session dropped), Ctrl-C, SIGQUIT and SIGTERM. Whatever happens, the exit pauses the
stream, sends the wheels 0 and puts the robot back in Passive mode, then reads the robot
back: "robot stopped (confirmed)" only when it answers so, else "stop sent, NOT confirmed"
and exit status 3. If this program is killed outright (SIGKILL, out of memory, a crash), a
guardian process sends the stop. The reason is printed and written to LOG's status file
next to it.

The log is written beside LOG and put in place once the robot answers: a robot that never
answers leaves an existing LOG as it was (with --overwrite too).

paths (counter-clockwise, turning left in place at each corner, from where the robot stands):
  square    4 sides of --side m (default 1.0 m)
  octagon   8 sides of --side m (default 0.5 m; about 1.2 m across)
  teleop    keyboard: w/s faster/slower, a/d turn, space stop, q quit

--port sim drives the built-in simulated Create (a pseudo-terminal speaking the same bytes)
in seed 004's 10 ft arena, starting at (0.75 m, 0.75 m) facing +x, and writes its true pose
as truth_pose records (the arena frame; with --save-frames, the arena's tags as truth_landmark
records too), so `fgslam run` scores against it; see docs/create.md.
"""

def _positive(kind):
    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
        if not value > 0:
            raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
        return value

    return parse


def _fraction(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not 0.0 <= value < 1.0:
        raise argparse.ArgumentTypeError(f"must be in [0, 1), got {text}")
    return value


def add_parser(verbs) -> argparse.ArgumentParser:
    """Add ``fgslam record`` to the sub-parsers ``verbs``; returns its parser."""
    p = add_verb(
        verbs, "record",
        help=help_of("record"),
        description=RECORD_DESCRIPTION,
    )
    p.add_argument("--port", required=True, metavar="PORT",
                   help="serial port (/dev/ttyUSB0, /dev/serial/by-id/..., COM3, a pyserial URL), "
                        "or 'sim' for the built-in simulated Create")
    p.add_argument("--model", required=True, choices=("create1", "create2"),
                   help="create1: original Create, 57600 baud, odometry from packets 19/20; "
                        "create2: Roomba 600 based, 115200 baud, odometry from encoder counts 43/44")
    p.add_argument("--path", default="octagon", choices=("square", "octagon", "teleop"),
                   help="what to drive (default octagon)")
    p.add_argument("--out", required=True, metavar="LOG", help="run log to write (.jsonl); an existing one is kept")
    add_overwrite_option(p, "an existing LOG (and its .status.json)")
    p.add_argument("--side", type=_positive(float), default=None, metavar="M",
                   help="side of the square/octagon in metres (default 1.0 / 0.5)")
    p.add_argument("--laps", type=_positive(int), default=1, metavar="N", help="laps of the path (default 1)")
    p.add_argument("--speed", type=_positive(float), default=0.2, metavar="M_S",
                   help="speed on straights, m/s (default 0.2, at most 0.5)")
    p.add_argument("--turn-rate", type=_positive(float), default=0.8, metavar="RAD_S",
                   help="turn rate in place, rad/s (default 0.8)")
    p.add_argument("--mode", choices=("safe", "full"), default="safe",
                   help="OI mode: safe (default; the robot also stops itself on cliffs and wheel drops) "
                        "or full (no robot-side checks: for testing on a stand only)")
    p.add_argument("--baud", type=_positive(int), default=None,
                   help="baud rate (default 57600 for create1, 115200 for create2)")
    p.add_argument("--calibration", default=None, metavar="FILE",
                   help="noise from `fgslam calibrate --out FILE` (default: nominal, uncalibrated values)")
    p.add_argument("--watchdog", type=_positive(float), default=0.5, metavar="S",
                   help="stop the robot when the control loop sends no command, or no valid sensor reading "
                        "arrives, for S seconds of wall time (default 0.5; more for a slow computer)")
    p.add_argument("--max-duration", type=_positive(float), default=None, metavar="S",
                   help="stop after this many seconds")
    sim = p.add_argument_group("simulated Create (--port sim)")
    sim.add_argument("--sim-seed", type=int, default=0, metavar="N", help="random seed of the encoder noise (default 0)")
    sim.add_argument("--sim-time-scale", type=_positive(float), default=1.0, metavar="X",
                     help="run the simulation X times faster than real time (default 1)")
    sim.add_argument("--sim-corrupt", type=_fraction, default=0.0, metavar="P",
                     help="damage this fraction of the robot's bytes (default 0)")
    sim.add_argument("--sim-drop", type=_fraction, default=0.0, metavar="P",
                     help="drop this fraction of the robot's bytes (default 0)")
    cam = p.add_argument_group("camera frames (fgslam detect FOLDER --camera CAM.yaml --out LOG adds their landmarks afterwards)")
    cam.add_argument("--save-frames", default=None, metavar="FOLDER",
                     help="save a camera frame at each odometry record, stamped on the log's clock, as a TUM RGB-D "
                     "folder (a new or empty folder)")
    cam.add_argument("--frames", default=None, metavar="SOURCE",
                     help="camera:N (OpenCV) or kinect:N (RGB + registered depth); with --port sim the default is "
                     "the simulated camera (seed 004's arena tags rendered from the true pose, camera.yaml written)")
    p.set_defaults(func=cmd_record)
    return p


def _frame_saver(args, sim, settings, truth=None):
    """A :class:`fgslam.record_frames.FrameSaver` for --save-frames (the simulated camera with --port
    sim: each frame rendered at the pose ``truth``, a :class:`fgslam.record_truth.TruthWriter`, has
    just written, and the arena's tags given to it as truth landmarks)."""
    from fgslam.record_frames import FrameSaver

    folder = Path(args.save_frames)
    if folder.exists() and (not folder.is_dir() or any(folder.iterdir())):
        raise FgslamError(f"--save-frames {folder}: give a new or empty folder (frames already there would mix)")
    source = args.frames or ("sim" if sim is not None else None)
    if source == "sim":
        if sim is None:
            raise FgslamError("--frames sim needs --port sim")
        from fgslam.live import simulated_camera
        from slamio.camera.model import save_camera

        render_at, front_end, tags = simulated_camera(sim, seed=args.sim_seed)

        def grab_for(index, odometry):  # the very pose written as truth for this record
            return render_at(index, odometry, true_pose=truth.last_pose if truth is not None else None)

        if truth is not None:
            truth.truth_landmarks = tuple(tags)
        folder.mkdir(parents=True, exist_ok=True)
        save_camera(folder / "camera.yaml", front_end.camera, comment="the simulated camera of fgslam record")
    else:
        from fgslam.live import LatestFrame
        from slamio.camera.sources import kinect_frames, video_frames

        kind, _, number = (source or "").partition(":")
        if kind not in ("camera", "kinect") or not number.isdigit():
            raise FgslamError(f"--save-frames needs --frames camera:N or kinect:N, got {source!r}")
        frames = video_frames(int(number)) if kind == "camera" else kinect_frames(int(number))
        grab_for = LatestFrame(frames).grab_for
    return FrameSaver(folder, grab_for, settings.record_period_s)


def cmd_record(args: argparse.Namespace) -> int:
    from slamio.noise.trials import load_calibration
    from slamio.create.record_settings import RecorderSettings

    # Before the port is opened and the recorder starts the log: an existing recording is never
    # emptied unless --overwrite, and a place that cannot be written is one line, not a traceback.
    out = check_new_file(args.out, overwrite=args.overwrite)
    if args.speed > 0.5:
        raise FgslamError(f"--speed {args.speed} m/s is above the Create's 0.5 m/s")
    if args.frames is not None and args.save_frames is None:
        raise FgslamError(f"--frames {args.frames} is the camera of --save-frames FOLDER, which is not given: add "
                          "--save-frames FOLDER to save its frames, or leave --frames out")
    check_number("--watchdog", args.watchdog, above=0, what="seconds of wall time, e.g. 0.5")
    settings = RecorderSettings(speed_m_s=args.speed, turn_rate_rad_s=args.turn_rate, mode=args.mode,
                                max_duration_s=args.max_duration, command_timeout_s=args.watchdog,
                                data_timeout_s=args.watchdog)
    noise = observation = trials = None
    if args.calibration:
        calibration = load_calibration(args.calibration)
        trials = calibration.to_dict()  # the header keeps it whole: seed 001's EKF takes R and Q from it
        noise = calibration.odometry_noise(args.model)
        if calibration.observation is not None:
            observation = {"model": "range-bearing, from fgslam calibrate", **calibration.observation}
    source = {
        "command": command_line(args) if getattr(args, "argv", None) is not None else None,
        "path": args.path,
        "side_m": args.side,
        "laps": args.laps,
    }

    out.parent.mkdir(parents=True, exist_ok=True)
    with robot_session((out, "--out")) as signals:  # one writer per log; every terminating signal stops the robot
        check_new_file(out, overwrite=args.overwrite)  # again, under the lock: another recorder may have made it
        return _record_run(args, out, settings, noise, observation, trials, source, signals)


def _record_run(args, out: Path, settings, noise, observation, trials, source, signals) -> int:
    """Start the simulator (--port sim), open the link, record, write the status file and
    say how it ended (:mod:`fgslam.cli.robot_end`)."""
    from slamio.create.link import CreateLink
    from slamio.create.controllers import TELEOP_HELP, PathController, TeleopController, TerminalKeys, path_moves
    from slamio.create.record import record

    sim = None
    port, clock = args.port, None
    if args.port == "sim":
        from slamio.create.sim import SimulatedCreate
        from slamio.create.sim_model import without_sideways

        # The simulated encoders err as the log's header says (a calibration's model when given).
        sim = SimulatedCreate(args.model, seed=args.sim_seed, time_scale=args.sim_time_scale,
                              corrupt_fraction=args.sim_corrupt, drop_fraction=args.sim_drop,
                              odometry_noise=None if noise is None else without_sideways(noise)).start()
        noise = sim.odometry_noise
        port, clock = sim.port, sim.clock
        source["simulator"] = {"seed": args.sim_seed, "time_scale": args.sim_time_scale,
                               "corrupt_fraction": args.sim_corrupt, "drop_fraction": args.sim_drop}
    saver = link = truth = None
    status = status_path(out)
    if sim is not None:  # the simulator knows where the robot really is: the log gets its truth
        from fgslam.record_truth import TRUTH_NOTE, TruthWriter
        from slamio.create.sim import DEFAULT_START_POSE

        truth = TruthWriter(lambda: sim.true_pose, record_period_s=settings.record_period_s)
        source["truth"] = TRUTH_NOTE

    def placed():  # the new log is in place: a status file of the log it replaced no longer fits
        for stale in stale_status_files(out):
            stale.unlink()

    try:
        if args.save_frames:
            saver = _frame_saver(args, sim, settings, truth)
            source["frames"] = str(args.save_frames)
        if truth is not None:
            truth.inner = saver
        link = CreateLink(port, args.model, baud=args.baud)
        link.open()  # a port that does not open is a user error (exit 1), before the log exists
        if sim is not None:  # the simulator waits for what this process has read (slamio.create.sim)
            sim.unread.host_bytes_read = lambda: link.bytes_read
        kwargs = dict(settings=settings, noise=noise, source=source, observation_noise=observation,
                      calibration=trials, hooks=truth or saver, overwrite=args.overwrite, signals=signals,
                      on_placed=placed)
        if clock is not None:
            kwargs["clock"] = clock
        if sim is not None:  # the world frame is the arena's, where the truth is
            kwargs["start_pose"] = DEFAULT_START_POSE
        if args.path == "teleop":
            with TerminalKeys() as keys:
                print(TELEOP_HELP, file=sys.stderr)
                result = record(link, out, TeleopController(keys, settings), **kwargs)
        else:
            moves = path_moves(args.path, args.side, args.laps)
            result = record(link, out, PathController(moves, settings), **kwargs)
    finally:
        with signals.held(raise_after=False):
            if link is not None:
                link.close()
            if saver is not None:
                saver.close()
            if sim is not None:
                sim.close()
    with signals.held(raise_after=False):  # the robot is stopped: what is left is to say so
        return _report(args, out, result, sim, saver, status, truth)


def _report(args, out: Path, result, sim, saver, status: Path, truth=None) -> int:
    from fgslam.atomic import write_text_whole
    from slamio.create.record_settings import status_of

    if result.log_placed:
        try:
            extra = _simulator_status(sim) if sim is not None else {}
            write_text_whole(status, json.dumps({**status_of(result), **extra}, indent=2) + "\n")
        except OSError as exc:  # a full disk: the log and the robot's outcome still get said
            say(f"fgslam record: warning: cannot write {status}: {exc.strerror or exc}")
    stats = result.link_stats
    quality = (f"{stats.get('frames_ok', 0)} frames, {stats.get('bad_frames', 0)} rejected"
               if stats.get("reader") == "stream"
               else f"{stats.get('answers', 0)} answers, {stats.get('lost_answers', 0)} lost")
    if result.log_placed:
        say(f"wrote {out}: {result.records} odometry records over {result.duration_s:.1f} s, "
            f"{result.distance_m:.3f} m driven, {result.angle_rad:.2f} rad turned ({quality})", sys.stdout)
        if truth is not None:
            say(f"  with {truth.written} truth_pose records (the simulator's true pose, arena frame)"
                + (f" and {len(truth.truth_landmarks)} truth_landmark records (the arena's tags)"
                   if truth.truth_landmarks else ""), sys.stdout)
    if saver is not None:
        say(f"saved {saver.saved} camera frames to {args.save_frames}/ ({saver.skipped} skipped: the writer was "
            f"behind; {saver.missing} without an image)", sys.stdout)
    return report_end("record", result, out)


def _simulator_status(sim) -> dict:
    """The simulator's ground truth for the status file of a --port sim recording."""
    return {"simulator": {
        "true_pose": list(sim.true_pose),
        "true_path_length_m": sim.true_path_length_m,
        "encoder_distance_m": sim.encoder_distance_m,  # what the encoders counted, noise included
        "encoder_turn_rad": sim.encoder_turn_rad,
        "commanded_mm_s": list(sim.commanded_mm_s),
        "oi_mode": int(sim.mode),
        "frames_sent": sim.frames_sent,
        "bytes_corrupted": sim.bytes_corrupted,
        "bytes_dropped": sim.bytes_dropped,
    }}

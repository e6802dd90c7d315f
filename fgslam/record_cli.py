"""The ``fgslam record`` and ``fgslam calibrate`` verbs (wired into ``fgslam.cli``).

``add_record_parser(verbs)`` and ``add_calibrate_parser(verbs)`` take the sub-parsers
object of ``fgslam.cli.build_parser`` and add one verb each; the handlers return the exit
status and raise :class:`~slamio.errors.FgslamError` for mistakes the user can fix.
``python -m fgslam.record_cli record ...`` is the same as ``fgslam record ...``.

Exit status of ``fgslam record``: 0 when the path was driven to the end (or teleop quit),
2 when the robot was stopped early (bump, wheel drop, watchdog, no data, serial error,
time limit; the log is kept and the reason printed), 130 on Ctrl-C/SIGTERM, 1 on a user
error (bad option, port that does not open).
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from pathlib import Path
from typing import Sequence

from slamio.errors import FgslamError

__all__ = ["add_record_parser", "add_calibrate_parser", "cmd_record", "cmd_calibrate", "main"]

EXIT_STOPPED_EARLY = 2
EXIT_INTERRUPTED = 130

RECORD_DESCRIPTION = """\
Drive an iRobot Create along a scripted path (or from the keyboard) and write its odometry
to a run log, one record every 0.1 s, flushed as written: a recorder that is killed leaves
every record but at most the last.

The robot stops (and the log is kept) on a bump, a wheel drop, when it leaves Safe mode,
when the host stops sending commands for 0.5 s (watchdog), when no valid sensor data comes
for 0.5 s, on Ctrl-C, and when the serial port fails. Whatever happens, the exit sends
Drive Direct 0 0 and puts the robot back in Passive mode. The reason is printed and written
to LOG's .status.json file next to it.

paths (counter-clockwise, turning left in place at each corner, from where the robot stands):
  square    4 sides of --side m (default 1.0 m)
  octagon   8 sides of --side m (default 0.5 m; about 1.2 m across)
  teleop    keyboard: w/s faster/slower, a/d turn, space stop, q quit

--port sim drives the built-in simulated Create (a pseudo-terminal speaking the same bytes)
in seed 004's 10 ft arena, starting at (0.75 m, 0.75 m) facing +x; see docs/create.md.
"""

CALIBRATE_DESCRIPTION = """\
Two ways to learn the noise:

fgslam calibrate LOG.jsonl [LOG.jsonl ...] --out noise.json
  Fit a noise model against the ground truth in run logs (motion capture, a simulator):
  odometry lag, scale, turn per metre and variance rates; the camera's range model (range
  or depth, scale, bias), bearing scale and bias, latency, sigmas that grow with range and
  turn rate, and the outlier rate (slamio.noise_fit). Several logs are pooled. Use the file
  on *other* runs: fgslam import mrclam SOURCE OUT --robot N --noise noise.json. Fit on logs
  imported without --noise.

fgslam calibrate TRIALS.csv [--out cal.json]
  Compute motion and measurement noise from measured trials, the way seed 001 did: drive
forward (and turn in place) many times, tape-measure where the robot really ended, and take
the covariance of the errors. Prints the biases and standard deviations; --out writes the
JSON that `fgslam record --calibration` puts in the log header and uses for the odometry
covariances.

TRIALS.csv columns (blank where a column does not apply, # starts a comment):
  kind,command_distance_m,command_angle_rad,x_m,y_m,theta_rad,true_range_m,true_bearing_rad,range_m,bearing_rad
  forward,0.5,0,0.497,0.004,0.012,,,,            drove 0.5 m, ended at x,y,theta (start frame)
  rotate,0,1.5708,0.002,-0.001,1.553,,,,         turned 90 deg in place
  sensor,,,,,,1.20,0.10,1.23,0.09                landmark truly at 1.20 m, 0.10 rad; read 1.23, 0.09
data/calibration_trials_s001.csv is a (simulated) example.
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


def add_record_parser(verbs) -> argparse.ArgumentParser:
    """Add ``fgslam record`` to the sub-parsers ``verbs``; returns its parser."""
    p = verbs.add_parser(
        "record",
        help="drive an iRobot Create (or the simulated one) and record its odometry to a run log",
        description=RECORD_DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--port", required=True, metavar="PORT",
                   help="serial port (/dev/ttyUSB0, /dev/serial/by-id/..., COM3, a pyserial URL), "
                        "or 'sim' for the built-in simulated Create")
    p.add_argument("--model", required=True, choices=("create1", "create2"),
                   help="create1: original Create, 57600 baud, odometry from packets 19/20; "
                        "create2: Roomba 600 based, 115200 baud, odometry from encoder counts 43/44")
    p.add_argument("--path", default="octagon", choices=("square", "octagon", "teleop"),
                   help="what to drive (default octagon)")
    p.add_argument("--out", required=True, metavar="LOG", help="run log to write (.jsonl)")
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
    p.set_defaults(func=cmd_record)
    return p


def add_calibrate_parser(verbs) -> argparse.ArgumentParser:
    """Add ``fgslam calibrate`` to the sub-parsers ``verbs``; returns its parser."""
    p = verbs.add_parser(
        "calibrate",
        help="noise covariances from measured forward/rotate/sensor trials (seed 001's method)",
        description=CALIBRATE_DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("trials", nargs="+", metavar="TRIALS.csv | LOG.jsonl",
                   help="the measured trials (one .csv), or run logs with ground truth (.jsonl, one or more)")
    p.add_argument("--out", default=None, metavar="FILE",
                   help="write the calibration (trials) or noise model (logs) JSON here; an existing file is not replaced")
    p.set_defaults(func=cmd_calibrate)
    return p


# --------------------------------------------------------------------------- handlers


def _status_path(out: Path) -> Path:
    return out.with_name(out.stem + ".status.json") if out.suffix else out.with_name(out.name + ".status.json")


def cmd_record(args: argparse.Namespace) -> int:
    from slamio.create.calibrate import load_calibration
    from slamio.create.link import CreateLink
    from slamio.create.record import (
        TELEOP_HELP,
        PathController,
        RecorderSettings,
        TeleopController,
        TerminalKeys,
        path_moves,
        record,
        write_status,
    )

    out = Path(args.out)
    if out.is_dir():
        raise FgslamError(f"--out {out} is a folder; give a file name such as {out / 'run.jsonl'}")
    out.parent.mkdir(parents=True, exist_ok=True)
    if args.speed > 0.5:
        raise FgslamError(f"--speed {args.speed} m/s is above the Create's 0.5 m/s")
    settings = RecorderSettings(speed_m_s=args.speed, turn_rate_rad_s=args.turn_rate, mode=args.mode,
                                max_duration_s=args.max_duration)
    noise = observation = None
    if args.calibration:
        calibration = load_calibration(args.calibration)
        noise = calibration.odometry_noise(args.model)
        if calibration.observation is not None:
            observation = {"model": "range-bearing, from fgslam calibrate", **calibration.observation}
    argv = getattr(args, "argv", None)
    source = {
        "command": "fgslam " + " ".join(shlex.quote(a) for a in argv) if argv is not None else None,
        "path": args.path,
        "side_m": args.side,
        "laps": args.laps,
    }

    sim = None
    port, clock = args.port, None
    if args.port == "sim":
        from slamio.create.sim import SimulatedCreate

        sim = SimulatedCreate(args.model, seed=args.sim_seed, time_scale=args.sim_time_scale,
                              corrupt_fraction=args.sim_corrupt, drop_fraction=args.sim_drop).start()
        port, clock = sim.port, sim.clock
        source["simulator"] = {"seed": args.sim_seed, "time_scale": args.sim_time_scale,
                               "corrupt_fraction": args.sim_corrupt, "drop_fraction": args.sim_drop}
    try:
        link = CreateLink(port, args.model, baud=args.baud)
        link.open()  # a port that does not open is a user error (exit 1), before the log exists
        kwargs = dict(settings=settings, noise=noise, source=source, observation_noise=observation)
        if clock is not None:
            kwargs["clock"] = clock
        if args.path == "teleop":
            with TerminalKeys() as keys:
                print(TELEOP_HELP, file=sys.stderr)
                result = record(link, out, TeleopController(keys, settings), **kwargs)
        else:
            moves = path_moves(args.path, args.side, args.laps)
            result = record(link, out, PathController(moves, settings), **kwargs)
    finally:
        if "link" in locals():
            link.close()
        if sim is not None:
            sim.close()
    write_status(result, _status_path(out))
    if sim is not None:  # add the ground truth to the status file
        status = json.loads(_status_path(out).read_text())
        status["simulator"] = {
            "true_pose": list(sim.true_pose),
            "true_path_length_m": sim.true_path_length_m,
            "commanded_mm_s": list(sim.commanded_mm_s),
            "oi_mode": int(sim.mode),
            "frames_sent": sim.frames_sent,
            "bytes_corrupted": sim.bytes_corrupted,
            "bytes_dropped": sim.bytes_dropped,
        }
        _status_path(out).write_text(json.dumps(status, indent=2) + "\n")

    stats = result.link_stats
    quality = (f"{stats.get('frames_ok', 0)} frames, {stats.get('bad_frames', 0)} rejected"
               if stats.get("reader") == "stream"
               else f"{stats.get('answers', 0)} answers, {stats.get('lost_answers', 0)} lost")
    print(f"wrote {out}: {result.records} odometry records over {result.duration_s:.1f} s, "
          f"{result.distance_m:.3f} m driven, {result.angle_rad:.2f} rad turned ({quality})")
    if result.shutdown is not None and not result.shutdown.stopped:
        print(f"fgslam record: WARNING: {result.shutdown.detail}", file=sys.stderr)
    if result.reason.kind == "interrupted":
        print(f"fgslam record: {result.reason}", file=sys.stderr)
        return EXIT_INTERRUPTED
    if result.reason.is_fault:
        print(f"fgslam record: stopped early: {result.reason}; the log keeps the {result.records} records "
              f"before it", file=sys.stderr)
        return EXIT_STOPPED_EARLY
    print(f"stopped: {result.reason}")
    return 0


def cmd_calibrate(args: argparse.Namespace) -> int:
    logs = [p for p in args.trials if p.endswith(".jsonl")]
    if logs:
        return _calibrate_from_logs(args, logs)
    if len(args.trials) != 1:
        raise FgslamError(
            f"calibrate takes one TRIALS.csv or one or more LOG.jsonl, got {' '.join(args.trials)}"
        )
    from slamio.create.calibrate import calibrate, read_trials

    args.trials = args.trials[0]
    motion, sensor = read_trials(args.trials)
    calibration = calibrate(motion, sensor, source=args.trials)
    print(calibration.summary())
    if args.out:
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(calibration.to_dict(), indent=2) + "\n", encoding="utf-8")
        print(f"wrote {out}")
    return 0


def _calibrate_from_logs(args: argparse.Namespace, paths: list[str]) -> int:
    """``fgslam calibrate LOG.jsonl...``: fit a noise model against the logs' ground truth."""
    from fgslam.cli import _read
    from slamio.noise_fit import fit_noise_model
    from slamio.noise_model import save_noise_model

    others = [p for p in args.trials if not p.endswith(".jsonl")]
    if others:
        raise FgslamError(f"calibrate: mix of logs and other files ({' '.join(others)}); give only .jsonl logs")
    if args.out and Path(args.out).exists():  # before the fit, so nothing is computed for nothing
        raise FgslamError(f"{args.out} exists; choose another --out or delete it first")
    model = fit_noise_model([_read(p) for p in paths])
    print(noise_model_summary(model))
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        save_noise_model(args.out, model)
        print(f"wrote {args.out}")
    return 0


def noise_model_summary(model) -> str:
    """A few lines a person reads: the fitted model in the units people think in."""
    o, z = model.odometry, model.observation
    n = o.noise
    return "\n".join([
        f"noise model fitted on {len(model.fitted_on)} log(s): {', '.join(model.fitted_on)}",
        f"odometry: lag {o.lag_s:.3f} s, forward scale {o.forward_scale:.4f}, turn scale {o.turn_scale:.4f}, "
        f"turn per metre {o.turn_per_m_rad:+.4f} rad/m",
        f"  sigma per sqrt(m): forward {n.forward_m2_per_m ** 0.5:.4f} m, sideways {n.lateral_m2_per_m ** 0.5:.4f} m, "
        f"heading {n.heading_rad2_per_m ** 0.5:.4f} rad; per sqrt(rad) turned {n.heading_rad2_per_rad ** 0.5:.4f} rad; "
        f"per sqrt(s): {n.forward_m2_per_s ** 0.5:.4f} m, {n.lateral_m2_per_s ** 0.5:.4f} m, {n.heading_rad2_per_s ** 0.5:.4f} rad",
        f"camera: range is {'depth (r cos b)' if z.range_is_depth else 'Euclidean range'}, "
        f"measured = {z.range_scale:.4f} x {z.range_bias_m:+.4f} m; bearing = {z.bearing_scale:.4f} b {z.bearing_bias_rad:+.4f} rad; "
        f"latency {z.camera_latency_s:.3f} s",
        f"  sigma range = hypot({z.range_sigma_m:.4f} m, {z.range_sigma_per_m:.4f} x range); "
        f"sigma bearing = hypot({z.bearing_sigma_rad:.4f} rad, {z.bearing_sigma_s:.4f} s x turn rate); "
        f"outliers {100 * z.outlier_rate:.2f} %",
    ])


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m fgslam.record_cli record|calibrate ...``: the ``fgslam`` command itself
    (kept so scripts and tests that start the recorder as a module keep working)."""
    from fgslam.cli import main as fgslam_main

    return fgslam_main(argv)


if __name__ == "__main__":
    sys.exit(main())

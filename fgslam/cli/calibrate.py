"""``fgslam calibrate``: the noise of the odometry and the landmark readings, three ways.

* **from truth** (``fgslam calibrate LOG.jsonl... --out noise.json``): fit a noise model
  against the logs' ground truth (:mod:`slamio.noise.fit_truth`);
* **without truth** (``fgslam calibrate LOG.jsonl... --without-truth --out noise.json``):
  learn the noise from how the logs' own measurements agree once smoothed
  (:mod:`fgslam.self_calibration`);
* **from trials** (``fgslam calibrate TRIALS.csv [--out cal.json]``): seed 001's trial
  calibration, covariances of tape-measured trials (:mod:`slamio.noise.trials`).

The files say which (``.jsonl`` run logs, or one trials CSV); ``--from truth|trials`` names
it. Not the camera's intrinsics: that is ``fgslam calibrate-camera``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from fgslam.cli.common import (add_overwrite_option, add_verb, check_new_file, check_number, holds_outputs, read,
                               write_new_file)
from fgslam.cli.verbs import help_of
from slamio.errors import FgslamError
from slamio.noise.errors import NoiseModelError

#: The modes of ``fgslam calibrate`` (``--from``; ``self`` is ``--without-truth``).
MODES = ("truth", "self", "trials")

CALIBRATE_DESCRIPTION = """\
Learn the noise of the odometry and of the landmark readings, one of three ways. The files
given choose the way (run logs end in .jsonl; anything else is one trials CSV), or --from
names it: --from truth reads every file as a run log, whatever its name; --without-truth
(= --from self) learns from logs without truth; --from trials takes one CSV. (A camera's
intrinsics and lens distortion are not this: use fgslam calibrate-camera.)

without truth: fgslam calibrate LOG.jsonl [LOG.jsonl ...] --without-truth --out noise.json
  What a robot without motion capture can learn from its own runs: the variance rates of
  the odometry (per metre, per radian, per second) and the sigmas of range (growing with
  range) and bearing (growing with turn rate), and the outlier rate, by variance-component
  estimation on the batch solution (fgslam.self_calibration); the odometry's lag and the
  camera's range model (range or depth along its axis, and its bias). It cannot see scales,
  the bearing's bias or the camera's latency: those stay 1 and 0, and the summary lists
  them, and any rate the data cannot separate from another. --scales-from TRIALS.csv (or
  the CAL.json made from it) holds the odometry's forward and turn scales and its turn per
  metre at what a few taped drives and turns in place measured. fgslam run LOG --noise self
  fits on the log itself first (with --calibration CAL.json: holding its scales). Planar
  logs only for now.

from truth:   fgslam calibrate LOG.jsonl [LOG.jsonl ...] --out noise.json [--from truth]
  Fit a noise model against the ground truth in run logs (motion capture, a simulator):
  odometry lag, scale, turn per metre and variance rates; the camera's range model (range
  or depth, scale, bias), bearing scale and bias, latency, sigmas that grow with range and
  turn rate, the outlier rate and the readings' correlation in time (slamio.noise.fit_truth;
  range-only radios: slamio.noise.range), and where the sensor sits on the robot (x, y, yaw,
  from the bearings' parallax: slamio.noise.mount_fit), reported; with --fit-mount the model
  is fitted from there and carries it, and applying the model states it in the log header's
  sensor.pose_on_robot. Several logs are pooled. Use the file on *other*
  runs: fgslam import mrclam SOURCE OUT --robot N --noise noise.json, or fgslam run LOG
  --noise noise.json. Fit on logs imported without --noise.

from trials:  fgslam calibrate TRIALS.csv [--out cal.json] [--from trials]
  Seed 001's trial calibration (slamio.noise.trials): motion and measurement covariances
  from measured trials. Drive forward (and turn in place) many times, tape-measure where
  the robot really ended, and take the covariance of the errors. Prints the biases and
  standard deviations; --out writes the JSON that `fgslam record --calibration` puts in the
  log header and `fgslam run --calibration` uses for the odometry covariances.

TRIALS.csv columns (blank where a column does not apply, # starts a comment):
  kind,command_distance_m,command_angle_rad,x_m,y_m,theta_rad,true_range_m,true_bearing_rad,range_m,bearing_rad
  forward,0.5,0,0.497,0.004,0.012,,,,            drove 0.5 m, ended at x,y,theta (start frame)
  rotate,0,1.5708,0.002,-0.001,1.553,,,,         turned 90 deg in place
  sensor,,,,,,1.20,0.10,1.23,0.09                landmark truly at 1.20 m, 0.10 rad; read 1.23, 0.09
data/calibration_trials_s001.csv is a (simulated) example.
"""


def add_parser(verbs) -> argparse.ArgumentParser:
    """Add ``fgslam calibrate`` to the sub-parsers ``verbs``; returns its parser."""
    p = add_verb(
        verbs, "calibrate",
        help=help_of("calibrate"),
        description=CALIBRATE_DESCRIPTION,
    )
    p.add_argument("trials", nargs="+", metavar="LOG.jsonl|TRIALS.csv",
                   help="run logs with ground truth (.jsonl, one or more: from truth), or the measured trials "
                   "(one CSV: from trials)")
    p.add_argument("--from", dest="mode", choices=MODES, default=None,
                   help="name the way instead of reading it from the files: truth (fit a noise model on the "
                   "logs' ground truth; every file is read as a run log) or trials (seed 001's trial "
                   "calibration of one TRIALS.csv)")
    p.add_argument("--without-truth", dest="mode", action="store_const", const="self",
                   help="learn the noise from the logs alone (no ground truth needed): variance-component "
                   "estimation on the smoothed solution; the same as --from self")
    p.add_argument("--odometry-window", type=float, default=None, metavar="S",
                   help="the stretch of driving, in seconds, the odometry's variance rates are fitted over (from "
                   "truth: default 1; without truth: default each step, with S the steps chained over S seconds "
                   "against the smoothed solution): a longer one describes the error the estimator carries "
                   "through long stretches without a reading (more consistent, less accurate; "
                   "docs/results-datasets.md)")
    p.add_argument("--fit-mount", action="store_true",
                   help="(from truth) fit the model from where the bearings place the sensor on the robot and "
                   "carry it: applying the model states it as the log header's sensor.pose_on_robot (without "
                   "it the fitted mount is only reported)")
    p.add_argument("--scales-from", default=None, metavar="CAL.json|TRIALS.csv",
                   help="(without truth) hold the odometry's forward and turn scales and its turn per metre at "
                   "what measured trials say (a calibration from `fgslam calibrate TRIALS.csv --out CAL.json`, or "
                   "the trials CSV itself): what the run alone cannot tell, a taped distance and turns in place can")
    p.add_argument("--out", default=None, metavar="FILE",
                   help="write the noise model (from truth) or the trial calibration (from trials) JSON here; "
                   "an existing file is kept")
    add_overwrite_option(p, "an existing --out FILE")
    p.set_defaults(func=cmd_calibrate)
    return p


# --------------------------------------------------------------------------- handlers


def calibration_mode(paths: list[str], mode: str | None) -> str:
    """Which way ``fgslam calibrate paths`` calibrates: ``"truth"`` or ``"trials"`` (``mode``,
    from ``--from``, or read from the files: any ``.jsonl`` is a run log); one
    :class:`NoiseModelError` line when the files do not fit it."""
    logs = [p for p in paths if p.endswith(".jsonl")]
    others = [p for p in paths if not p.endswith(".jsonl")]
    if mode is None:  # read from the files
        if logs and others:
            raise NoiseModelError(
                f"calibrate: mix of logs and other files ({' '.join(others)}); give only .jsonl logs (from truth) "
                "or one TRIALS.csv (from trials)"
            )
        mode = "truth" if logs else "trials"
    if mode == "self" and others and not logs:
        raise NoiseModelError(f"calibrate --without-truth takes run logs (.jsonl), got {' '.join(paths)}")
    if mode == "trials" and (logs or len(paths) != 1):  # --from truth takes logs of any name
        raise NoiseModelError(
            f"calibrate from trials takes one TRIALS.csv, got {' '.join(paths)}; run logs with ground truth "
            "(.jsonl, one or more) are calibrated from truth"
        )
    return mode


@holds_outputs(out="--out")
def cmd_calibrate(args: argparse.Namespace) -> int:
    mode = calibration_mode(args.trials, getattr(args, "mode", None))
    if getattr(args, "fit_mount", False) and mode != "truth":
        raise FgslamError("--fit-mount fits the sensor's mount against ground truth: it works with logs that have "
                          "truth (--from truth), not " + ("without truth" if mode == "self" else "with trials"))
    if getattr(args, "scales_from", None) is not None and mode != "self":
        raise FgslamError("--scales-from holds the odometry's scales while the rest is learned without truth: "
                          "use it with --without-truth")
    if mode == "truth":
        return _calibrate_from_logs(args, args.trials)
    if mode == "self":
        return _calibrate_without_truth(args, args.trials)
    from slamio.noise.trials import calibrate_from_trials, read_trials

    trials = args.trials[0]
    if args.out:  # before the work: an existing file is kept unless --overwrite
        check_new_file(args.out, overwrite=args.overwrite, example="calibration.json")
    motion, sensor = read_trials(trials)
    calibration = calibrate_from_trials(motion, sensor, source=trials)
    print(calibration.summary())
    if args.out:
        text = json.dumps(calibration.to_dict(), indent=2) + "\n"
        write_new_file(Path(args.out), lambda tmp: Path(tmp).write_text(text, encoding="utf-8"),
                       overwrite=args.overwrite)
        print(f"wrote {args.out}")
    return 0


def _calibrate_from_logs(args: argparse.Namespace, paths: list[str]) -> int:
    """``fgslam calibrate LOG.jsonl...`` (from truth): fit a noise model against the logs' ground truth."""
    from slamio.noise.fit_truth import fit_noise_model
    from slamio.noise.model import save_noise_model

    if args.out:  # before the fit, so nothing is computed for nothing
        check_new_file(args.out, overwrite=args.overwrite, example="noise.json")
    window = odometry_window(args, 1.0)
    model = fit_noise_model([read(p) for p in paths], fit_mount=getattr(args, "fit_mount", False), window_s=window)
    print(noise_model_summary(model))
    if args.out:
        write_new_file(Path(args.out), lambda tmp: save_noise_model(tmp, model, overwrite=True),
                       overwrite=args.overwrite)
        print(f"wrote {args.out}")
    return 0


def _calibrate_without_truth(args: argparse.Namespace, paths: list[str]) -> int:
    """``fgslam calibrate LOG.jsonl... --without-truth``: learn the noise from the logs alone."""
    from fgslam.cli.progress import Progress
    from fgslam.self_calibration import fit_without_truth
    from slamio.noise.model import save_noise_model

    if args.out:
        check_new_file(args.out, overwrite=args.overwrite, example="noise.json")
    pinned = None if getattr(args, "scales_from", None) is None else trial_scales(args.scales_from)
    window = odometry_window(args, None)
    logs = [read(p) for p in paths]
    with Progress(unit="") as progress:
        fit = fit_without_truth(logs, progress=progress, pinned=pinned, odometry_window_s=window)
    print(noise_model_summary(fit.model))
    print(self_fit_notes(fit))
    if args.out:
        write_new_file(Path(args.out), lambda tmp: save_noise_model(tmp, fit.model, overwrite=True),
                       overwrite=args.overwrite)
        print(f"wrote {args.out}")
    return 0


def odometry_window(args: argparse.Namespace, default: float | None) -> float | None:
    """``--odometry-window``'s seconds (``default`` when not given), checked."""
    window = getattr(args, "odometry_window", None)
    if window is None:
        return default
    check_number("--odometry-window", window, above=0.0, at_most=600.0,
                 what="the seconds of driving the odometry's variance rates are fitted over")
    return window


def trial_scales(path: str) -> dict[str, float]:
    """The odometry's scales measured by trials (:meth:`slamio.noise.trials.TrialCalibration.odometry_scales`),
    from a calibration JSON or the trials CSV itself, printed."""
    from slamio.noise.trials import calibrate_from_trials, load_calibration, read_trials

    calibration = calibrate_from_trials(*read_trials(path), source=path) if path.lower().endswith(".csv") \
        else load_calibration(path)
    scales = calibration.odometry_scales()
    if not scales:
        raise FgslamError(f"{path}: has no forward or rotate trials, so no odometry scale to hold; "
                          "drive forward and turn in place a few times and measure where the robot ended")
    print(f"odometry scales held at the trials' ({path}): " + ", ".join(f"{k} {v:.4f}" for k, v in scales.items()))
    return scales


def self_fit_notes(fit) -> str:
    """What a fit without truth could not learn, in lines a person reads."""
    report = fit.report
    lines = [f"learned without truth in {fit.iterations} iterations"
             + ("" if fit.converged else " (NOT converged: the values are the last iteration's)")
             + f"; {fit.readings} readings paired with landmarks"
             + (f", {fit.unpaired} never paired (left out)" if fit.unpaired else "")]
    if report["not_separated_by_this_data"]:
        lines.append("  not separated by this data (kept near their start; drive at other speeds and turn more "
                     "to learn them): " + ", ".join(report["not_separated_by_this_data"]))
    if report.get("range_only"):
        lines.append("  range-only readings (radios): applying the model (--noise) changes the ranges' scale and sigma "
                     "only and keeps the log's odometry, whose heading a range cannot check")
    if report.get("odometry_window_s"):
        lines.append(f"  odometry variance rates learned over {report['odometry_window_s']:g} s stretches of its steps "
                     "chained (the error it carries between readings), not step by step")
    lag = report.get("lag_from_readings")
    if lag:
        lines.append(f"  odometry lag {lag['lag_s']:.2f} s: what {lag['pairs']} pairs of readings of the same "
                     "landmarks show")
    camera = report.get("range_model_from_readings")
    if camera and "range_scale" in camera:
        lines.append(f"  radio ranges read {camera['range_scale']:.4f} x the distance: what the whole run's ranges "
                     "agree on best with the log's odometry taken as the measure of distance (only their ratio shows)")
        lines.append("  not learnable without truth: the odometry's scales and the readings' correlation in time")
        return "\n".join(lines)
    if camera:
        lines.append(f"  camera range: {'depth along the axis (r cos b)' if camera['range_is_depth'] else 'Euclidean'}"
                     f", reading {camera['range_bias_m']:+.3f} m long: what the whole run's readings agree on best")
    if report.get("odometry_scales_pinned"):
        lines.append("  held at the trials' values: " + ", ".join(report["odometry_scales_pinned"]))
        lines.append("  not learnable without truth (kept at scale 1, bias 0): range scale, bearing bias, the "
                     "camera's latency and the readings' correlation in time")
    else:
        lines.append("  not learnable without truth (kept at scale 1, bias 0; hold the odometry's with "
                     "--scales-from TRIALS.csv, or fit on a log with truth): forward and range scale (only their "
                     "ratio shows), turn scale, bearing bias, the camera's latency and the readings' correlation in time")
    return "\n".join(lines)


def noise_model_summary(model) -> str:
    """A few lines a person reads: the fitted model in the units people think in."""
    o, z = model.odometry, model.observation
    n = o.noise
    not_fitted = model.fit_report.get("odometry", {}).get("not_fitted")
    return "\n".join([
        f"noise model fitted on {len(model.fitted_on)} log(s): {', '.join(model.fitted_on)}",
        *([f"odometry: not fitted ({not_fitted})"] if not_fitted else [
            f"odometry: lag {o.lag_s:.3f} s, forward scale {o.forward_scale:.4f}, turn scale {o.turn_scale:.4f}, "
            f"turn per metre {o.turn_per_m_rad:+.4f} rad/m",
            f"  sigma per sqrt(m): forward {n.forward_m2_per_m ** 0.5:.4f} m, sideways {n.lateral_m2_per_m ** 0.5:.4f} m, "
            f"heading {n.heading_rad2_per_m ** 0.5:.4f} rad; per sqrt(rad) turned {n.heading_rad2_per_rad ** 0.5:.4f} rad; "
            f"per sqrt(s): {n.forward_m2_per_s ** 0.5:.4f} m, {n.lateral_m2_per_s ** 0.5:.4f} m, "
            f"{n.heading_rad2_per_s ** 0.5:.4f} rad"]),
        *(_radio_lines(model) if _is_radio_model(model) else [
            f"camera: range is {'depth (r cos b)' if z.range_is_depth else 'Euclidean range'}, "
            f"measured = {z.range_scale:.4f} x {z.range_bias_m:+.4f} m; bearing = {z.bearing_scale:.4f} b "
            f"{z.bearing_bias_rad:+.4f} rad; latency {z.camera_latency_s:.3f} s",
            f"  sigma range = hypot({z.range_sigma_m:.4f} m, {z.range_sigma_per_m:.4f} x range); "
            f"sigma bearing = hypot({z.bearing_sigma_rad:.4f} rad, {z.bearing_sigma_s:.4f} s x turn rate); "
            f"outliers {100 * z.outlier_rate:.2f} %",
            _mount_line(model)]),
        f"  readings of one landmark: {100 * z.correlated_share:.0f} % of the variance correlated in time, "
        f"correlation time {z.correlation_time_s:.1f} s" if z.correlated_share > 0 else
        "  readings of one landmark: errors independent in time",
    ])


def _mount_line(model) -> str:
    """Where the fit places the sensor on the robot (slamio.noise.mount_fit), and whether it is used."""
    fit = model.fit_report.get("observation", {}).get("sensor_mount", {})
    if "pose_on_robot" not in fit:
        return "  sensor on the robot: not fitted (too few bearings)"
    (x, y, yaw), (sx, sy, syaw) = fit["pose_on_robot"], fit["sigma"]
    where = f"x {x:+.3f} ± {sx:.3f} m, y {y:+.3f} ± {sy:.3f} m, yaw {yaw:+.4f} ± {syaw:.4f} rad"
    if fit.get("adopted"):
        return f"  sensor on the robot: {where} (applying the model states it as the log's sensor.pose_on_robot)"
    if not fit.get("determined"):
        return f"  sensor on the robot: {where}: not determined by these runs, the logs' own header stands"
    return (f"  sensor on the robot, as the bearings place it: {where}; not used (the logs' header stands): "
            "pass --fit-mount to fit the model from there and carry it")


def _is_radio_model(model) -> bool:
    """A model of range-only readings: fitted with truth (slamio.noise.range) or without."""
    return "constant_offset_fit" in model.fit_report.get("observation", {}) or bool(model.fit_report.get("range_only"))


def _radio_lines(model) -> list[str]:
    """The observation lines of a range-only model (ranging radios, slamio.noise.range)."""
    z, offset = model.observation, model.fit_report.get("observation", {}).get("constant_offset_fit")
    return [
        f"ranges (no bearing): measured = {z.range_scale:.4f} x distance {z.range_bias_m:+.4f} m"
        + (f" (a constant offset would be {offset['median_offset_m']:.2f} m, spread {offset['robust_spread_m']:.2f} m)"
           if offset else ""),
        f"  sigma range = hypot({z.range_sigma_m:.4f} m, {z.range_sigma_per_m:.4f} x range); "
        f"outliers {100 * z.outlier_rate:.2f} %",
    ]

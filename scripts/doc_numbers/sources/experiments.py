"""Measurements that are a script's experiment on images or on the shared data: the rendered
accuracy table, the AprilTag photos, seed 002's shapes, seed 003's drives, seed 004's paths,
MRCLAM Dataset 6. Each calls the function the script itself uses."""

from __future__ import annotations

import tempfile

from scripts.doc_numbers.quotes import Context

MRCLAM6 = "data/mrclam/MRCLAM_Dataset6"  # under the shared data folder
SEED003 = "data/seed003"
RGBD_REAL = "data/rgbd-real"


def camera_accuracy(context: Context) -> dict[str, list[str]]:
    """``python -m slamio.camera.accuracy``'s table: first cell → the numbers of its row."""
    from scripts.doc_numbers.readers import markdown_rows
    from slamio.camera.accuracy import error_table, format_table

    return markdown_rows(format_table(error_table()))


def real_corner_sigma(context: Context) -> tuple[float, int]:
    """σ_px of the refined corners on the pupil-labs photos, and the number of tags."""
    from slamio.camera.accuracy import real_corner_sigma_px

    return real_corner_sigma_px(context.root / "tests" / "data" / "apriltag-photos")


def apriltag_photos(context: Context) -> dict:
    """``scripts/bench_apriltag.py``'s numbers that are not times, on the NASA photos and the
    rendered tags: CONFIGS name → its row's columns (``union``, ``counted``, ``not_in_union``
    (false detections and duplicates), ``outside_counted`` (real tags outside the counted
    union), ``reference``, ``listed``, ``reference_max``/``_mean`` px, ``rendered``,
    ``rendered_frames``, ``rendered_max``/``_mean`` px); "refined" and "refined single pass" →
    the front-end's / the single pass's corners after ``refine_tag_corners`` against the listed
    ones (``matched``, ``max``, ``mean`` px, ``kept`` the detector's, ``detections``); "rendered
    refined" and "rendered refined single pass" → the same on the rendered tags against the
    truth (``found``, ``max``, ``mean``, ``p95`` px); "timing frames" → the 640×480 frames the
    times are measured on (``frames``, and the whole front-end's ``tags_per_frame``; by kind,
    ``robot_frames``/``robot_tags`` and ``nasa_frames``/``nasa_tags``)."""
    from scripts import bench_apriltag as script
    import cv2
    import numpy as np

    from slamio.camera.accuracy import read_corner_list
    from slamio.camera.apriltag import AprilTagDetector
    from slamio.camera.detect import FrontEnd, FrontEndConfig
    from slamio.camera.model import kinect_v1_default
    from slamio.camera.tag_passes import TagPasses
    from slamio.camera.tag_union import read_union

    photos = context.root / "tests" / "data" / "apriltag-photos"
    nasa = sorted(photos.glob("nasa_*.jpg"))
    images = [cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for p in nasa]
    listed = [read_corner_list(p.with_suffix(".txt")) for p in nasa]
    union = read_union(photos / "nasa_union.txt")
    camera, rendered = script.rendered_tags()
    out = {}
    for name, settings in script.CONFIGS:
        detector = TagPasses([AprilTagDetector(**p) for p in settings])
        score, reference, n_rendered, errors = script.accuracy_columns(detector, images, listed, nasa, union, rendered)
        out[name] = dict(union=score.found, counted=score.counted,
                         not_in_union=len(score.not_listed) + len(score.duplicates), outside_counted=score.found_other,
                         reference=reference.found, listed=reference.listed,
                         reference_max=reference.max_corner_error_px, reference_mean=reference.mean_corner_error_px,
                         rendered=n_rendered, rendered_frames=len(rendered), rendered_max=float(errors.max()),
                         rendered_mean=float(errors.mean()))
    single_pass = AprilTagDetector(**script.FIRST_PASS)
    for label, detector in (("", None), (" single pass", single_pass)):
        refined, kept = script.match_refined(images, listed, nasa, detector)
        out["refined" + label] = dict(matched=refined.found, max=refined.max_corner_error_px,
                                      mean=refined.mean_corner_error_px, kept=kept,
                                      detections=refined.found + len(refined.false_detections))
    front_end = FrontEnd(kinect_v1_default(), FrontEndConfig()).detector
    for label, detector in (("", front_end), (" single pass", single_pass)):
        found, errors = script.rendered_corner_errors(detector.detect, rendered, camera)
        out["rendered refined" + label] = dict(found=found, max=float(errors.max()), mean=float(errors.mean()),
                                               p95=float(np.percentile(errors, 95)))
    front = FrontEnd(kinect_v1_default(), FrontEndConfig(kind="apriltag", tag_size_m=0.16))
    frames = script.timing_frames(photos, images)
    robot = len(list(photos.glob("pupil_*.png")))  # timing_frames puts the robot-camera photos first
    robot_tags, nasa_tags = script.front_end_tags(front, frames[:robot]), script.front_end_tags(front, frames[robot:])
    out["timing frames"] = dict(frames=len(frames), tags_per_frame=(robot_tags + nasa_tags) / len(frames),
                                robot_frames=robot, robot_tags=robot_tags, nasa_frames=len(frames) - robot,
                                nasa_tags=nasa_tags)
    return out


def seed002_shapes(context: Context) -> dict:
    """``scripts/seed002_shapes.py``: the heights per shape, distance and bearing, and the
    summary over all frames (min, max, mean deviation in %, frames measured) per method."""
    import math

    from scripts import seed002_shapes as script

    rows = script.measure(2.0, 0)
    out: dict = {(r["shape"], r["distance_m"], r["bearing_deg"]): r for r in rows}
    for method in ("gheight", "pinhole"):
        dev = [100 * (r[method] / r["actual_m"] - 1) for r in rows if math.isfinite(r[method])]
        out[method] = {"min": min(dev), "max": max(dev), "mean": sum(dev) / len(dev), "measured": len(dev)}
    return out


def seed004_paths(tag_noise: str):
    """``scripts/seed004_paths.py --seeds 1-20 --jobs 2 --tag-noise T``: (path, seed) → its row."""
    def measure(context: Context) -> dict:
        from concurrent.futures import ProcessPoolExecutor

        from scripts import seed004_paths as script

        jobs = [(p, s) for s in range(1, 21) for p in script.PATHS]
        with ProcessPoolExecutor(max_workers=2) as pool:
            rows = pool.map(script.one_run, [j[0] for j in jobs], [j[1] for j in jobs], [tag_noise] * len(jobs))
            return {(r["scenario"], r["seed"]): r for r in rows}
    return measure


def seed003_drives(names_or_seeds, shared: bool):
    """``scripts/seed003_drives.py``'s first table: drive → estimator → ATE 3-D m (real drives
    against the batch smoother, simulated ones against the truth)."""
    def measure(context: Context) -> dict:
        from scripts import seed003_drives as script

        from ekf.drive3d import position_errors_m
        from slamio.datasets.seed003 import load_drive
        from slamio.sim3d import simulate_drive

        out = {}
        for item in names_or_seeds:
            drive = load_drive(context.shared / SEED003 / f"{item}.npz") if shared else simulate_drive(item)
            results, _, batch = script.run_all(drive)
            reference, _, _ = script.reference_of(drive, batch)
            out[item] = {name: position_errors_m(trajectory, reference)[0]
                         for name, (trajectory, _, _) in results.items()}
        return out
    return measure


def mrclam_dataset6(context: Context) -> dict:
    """``scripts/bench_mrclam.py SHARED/data/mrclam/MRCLAM_Dataset6 --estimators
    ekf,ekf-fej,isam2,dead_reckoning``: robot → estimator → its
    scores (each robot with the noise model fitted on the other four)."""
    import contextlib
    import io
    import json

    from scripts import bench_mrclam as script

    out = context.scratch / "mrclam6.json"
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        script.main([str(context.shared / MRCLAM6), "--estimators", "ekf,ekf-fej,isam2,dead_reckoning", "--json", str(out)])
    return {int(k): v for k, v in json.loads(out.read_text(encoding="utf-8"))["results"].items()}


def mrclam_dataset6_adaptive(context: Context) -> dict:
    """``scripts/mrclam_adaptive_noise.py SHARED/data/mrclam/MRCLAM_Dataset6 --open-loop --sim``:
    the adaptive-noise variants per robot and their medians, the open-loop bounds, the NIS by
    time since a landmark's previous reading (robot keys as ints)."""
    import contextlib
    import io
    import json

    from scripts import mrclam_adaptive_noise as script

    out = context.scratch / "mrclam6_adaptive.json"
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        script.main([str(context.shared / MRCLAM6), "--open-loop", "--sim", "--json", str(out)])
    result = json.loads(out.read_text(encoding="utf-8"))
    for variant in result["variants"].values():
        variant["robots"] = {int(k): v for k, v in variant["robots"].items()}
    for part in ("readings", "innovations"):
        result["open_loop"][part] = {int(k): v for k, v in result["open_loop"][part].items()}
    return result


def mrclam_dataset6_camera(context: Context) -> dict:
    """``scripts/mrclam_camera_tried.py SHARED/data/mrclam/MRCLAM_Dataset6``: the readings'
    error correlations by time and by place in the picture, the per-run picture-error oracle
    and the EKF with a picture decay (robot keys as ints)."""
    import contextlib
    import io
    import json

    from scripts import mrclam_camera_tried as script

    out = context.scratch / "mrclam6_camera.json"
    with contextlib.redirect_stdout(io.StringIO()):
        script.main([str(context.shared / MRCLAM6), "--json", str(out)])
    result = json.loads(out.read_text(encoding="utf-8"))
    for part in ("oracle", "ekf"):
        result[part] = {(int(k) if k.isdigit() else k): v for k, v in result[part].items()}
    return result


def mrclam_dataset6_motor_lens(context: Context) -> dict:
    """``scripts/mrclam_motor_lens_tried.py SHARED/data/mrclam/MRCLAM_Dataset6``: the motor-lag
    and lens-distortion fits (robot keys as ints)."""
    import contextlib
    import io
    import json

    from scripts import mrclam_motor_lens_tried as script

    out = context.scratch / "mrclam6_motor_lens.json"
    with contextlib.redirect_stdout(io.StringIO()):
        script.main([str(context.shared / MRCLAM6), "--json", str(out)])
    result = json.loads(out.read_text(encoding="utf-8"))
    result["motor"]["robots"] = {int(k): v for k, v in result["motor"]["robots"].items()}
    result["lens"] = {int(k): v for k, v in result["lens"].items()}
    return result


def mrclam_dataset6_hidden(context: Context) -> dict:
    """``scripts/bench_association_mrclam.py SHARED/data/mrclam/MRCLAM_Dataset6``: robot →
    estimator → association score and ATE with the barcodes withheld (and ATE with them)."""
    import contextlib
    import io
    import json

    from scripts import bench_association_mrclam as script

    out = context.scratch / "mrclam6_hidden.json"
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        script.main([str(context.shared / MRCLAM6), "--estimators", "ekf,ekf-fej,isam2", "--json", str(out)])
    return {int(k): v for k, v in json.loads(out.read_text(encoding="utf-8")).items()}


def seed001_association(context: Context) -> dict:
    """``scripts/seed001_association.py --spacings 0.25,0.5,0.75,1.0,1.5,2.0,3.0 --jobs 2``:
    (spacing m, noise scale) → variant → (share correct %, ATE m), medians over seeds 1–3."""
    import statistics
    from concurrent.futures import ProcessPoolExecutor

    from scripts import seed001_association as script

    jobs = [(sp, ns, seed) for sp in SEED001_SPACINGS for ns in SEED001_SCALES for seed in (1, 2, 3)]
    with ProcessPoolExecutor(max_workers=2) as pool:
        rows = list(pool.map(script.one_run, *zip(*jobs), [36] * len(jobs)))
    out = {}
    for sp in SEED001_SPACINGS:
        for ns in SEED001_SCALES:
            cell = [r for r in rows if r["spacing_m"] == sp and r["noise_scale"] == ns]
            out[(sp, ns)] = {name: (100 * statistics.median(r[name][0] for r in cell),
                                    statistics.median(r[name][1] for r in cell)) for name in script.VARIANTS}
    return out


SEED001_SPACINGS = (0.25, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0)
SEED001_SCALES = (0.5, 1.0, 2.0, 4.0)


def plaza_range_model(context: Context) -> dict:
    """``scripts/plaza_range_model.py``'s measurement: each Plaza run under the other run's
    fitted range model and under the default import (``results[(run, kind)][estimator]``:
    ``fgslam run``'s metrics plus ``ate_aligned_m`` and ``rotation_deg``), the fitted
    ``models``, their fit ``reports`` and the GT headings' ``turn_deg``."""
    from scripts import plaza_range_model as script

    return script.measure()


def colour_real(context: Context) -> dict[str, list[str]]:
    """``scripts/bench_colour_real.py ../shared/data/rgbd-real``'s two tables (real clutter per
    frame, composited cylinders per depth shift): first cell → the numbers of its row."""
    import contextlib
    import io

    from scripts import bench_colour_real as script
    from scripts.doc_numbers.readers import markdown_rows

    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        script.main([str(context.shared / RGBD_REAL)])
    return markdown_rows(printed.getvalue())


def exact_models_nees(context: Context) -> dict:
    """``scripts/live_nees.py --simulate 30``: the EKF's run means on 30 simulated octagon laps
    (``means``), how many are ``inside`` their independent-pose ``band``, ``runs_band``."""
    from scripts import live_nees as script

    return script.exact_models_reference(30)


def live_laps(context: Context) -> dict:
    """``scripts/live_nees.py --record 10``: ten lockstep octagon laps (seeds 1–10, reproducible),
    each scored with the EKF and iSAM2 (``scores``, as :func:`live_nees.score_log`, 100 draws)
    and the band of ten runs' mean NEES (``runs_band``)."""
    from scripts import live_nees as script
    from fgslam.compare import nees_band

    with tempfile.TemporaryDirectory(prefix="fgslam-live-laps-") as folder:
        scores = [script.score_log(path, ("ekf", "isam2"), 100) for path in script.recorded_laps(10, folder)]
    return {"scores": scores, "runs_band": nees_band(3, runs=10)}


def live_band(context: Context) -> dict:
    """The shipped live-simulation lap's EKF mean NEES and its band (100 redrawn copies), and
    the same readings stating ``factor`` × their σ (30 copies): factor → RunNeesBand."""
    from ekf import EkfSlam
    from fgslam.consistency import run_nees_band, with_stated_noise_scaled
    from slamio.log import read_log

    log = read_log(context.root / "tests" / "data" / "live-sim" / "octagon.jsonl")
    out = {1.0: run_nees_band(log, EkfSlam, draws=100)}
    for factor in (0.4, 0.5, 0.7):
        out[factor] = run_nees_band(with_stated_noise_scaled(log, factor), EkfSlam, draws=30)
    return out



def stereo_pixel_covariance(context: Context) -> dict:
    """``scripts/stereo_pixel_covariance.py``'s table with its defaults (σ_u 0.3 px, σ_v 1 px,
    ρ 0.95, seeds 1–5): told → estimator → key → median over the drives."""
    from scripts import stereo_pixel_covariance as script
    from slamio.stereo import rectified_pixel_covariance

    return script.medians([1, 2, 3, 4, 5], rectified_pixel_covariance(0.3, 1.0, 0.95))

"""The measurements behind the docs' numbers, by name: each is run once per check, however
many quoted numbers it feeds (:mod:`scripts.doc_numbers.quotes`)."""

from __future__ import annotations

from scripts.doc_numbers.quotes import Source
from scripts.doc_numbers.sources.experiments import (MRCLAM6, RGBD_REAL, SEED003, apriltag_photos, camera_accuracy,
                                             colour_real, exact_models_nees, live_band, live_laps, mrclam_dataset6,
                                             mrclam_dataset6_adaptive, mrclam_dataset6_camera, mrclam_dataset6_hidden,
                                             mrclam_dataset6_motor_lens,
                                             plaza_range_model,
                                             real_corner_sigma, seed001_association, seed002_shapes, seed003_drives,
                                             seed004_paths, stereo_pixel_covariance)
from scripts.doc_numbers.sources.runs import (ASSOCIATING, DEFAULT, OUTLIERS, PAPERS, ROBUST, against_truth, bundled,
                                      check_smoothed, ekf_without_gate, flaw_costs, hidden_ids, live_replay, monte_carlo_octagon,
                                      seed_sweep, sim_then_run, trial_calibration, victoria_park, window_arena)

SOURCES = [
    Source("octagon", f"fgslam run data/arena_octagon.jsonl --estimators {DEFAULT},{PAPERS},ekf-fej", "cheap",
           bundled("arena_octagon.jsonl", f"{DEFAULT},{PAPERS},ekf-fej")),
    Source("square-papers", f"fgslam run data/arena_square.jsonl --estimators {PAPERS}", "cheap",
           bundled("arena_square.jsonl", PAPERS, consistency=False)),
    Source("octagon-outliers", f"fgslam sim arena-octagon --seed 1 --outliers 0.1 --outlier-mode add; "
           f"fgslam run --estimators {ROBUST}", "cheap",
           sim_then_run("outliers", "arena-octagon", ROBUST, consistency=False, **OUTLIERS)),
    Source("octagon-hidden", "fgslam sim arena-octagon --seed 1 --hide-ids; fgslam run --estimators "
           f"{ASSOCIATING},isam2",
           "cheap", hidden_ids("arena-octagon")),
    Source("square-cylinders-hidden", "fgslam sim arena-square|cylinders --seed 1 --hide-ids; fgslam run "
           f"--estimators {ASSOCIATING},isam2", "slow", hidden_ids("arena-square", "cylinders")),
    Source("check-octagon", "fgslam check data/arena_octagon.jsonl --estimator ekf --against smoothed", "cheap",
           check_smoothed),
    Source("trial-calibration", "fgslam calibrate data/calibration_trials_s001.csv; fgslam run LOG --calibration",
           "cheap", trial_calibration),
    Source("flaw-costs", "python -m scripts.flaw_costs (+ fgslam sim cylinders --seed 1)", "slow", flaw_costs),
    Source("camera-accuracy", "python -m slamio.camera.accuracy", "slow", camera_accuracy),
    Source("tag-corner-sigma", "slamio.camera.accuracy.real_corner_sigma_px(tests/data/apriltag-photos)", "cheap",
           real_corner_sigma),
    Source("apriltag-photos", "python -m scripts.bench_apriltag (accuracy columns)", "slow", apriltag_photos),
    Source("colour-real", "python -m scripts.bench_colour_real ../shared/data/rgbd-real", "slow", colour_real,
           shared=RGBD_REAL),
    Source("seed002-shapes", "python -m scripts.seed002_shapes", "slow", seed002_shapes),
    Source("grid200", f"fgslam sim grid --landmarks 200 --seed 1; fgslam run --estimators {DEFAULT},isam2-fast,ekf-fej",
           "slow", sim_then_run("grid200", "grid", f"{DEFAULT},isam2-fast,ekf-fej", landmarks=200)),
    Source("grid200-hidden", f"fgslam sim grid --landmarks 200 --seed 1 --hide-ids; fgslam run --estimators "
           f"{ASSOCIATING},isam2", "slow",
           against_truth("grid200_hidden", "grid", ASSOCIATING, landmarks=200, hide_ids=True)),
    Source("victoria-park", "fgslam import victoria-park vp.jsonl; fgslam run vp.jsonl --estimators "
           "ekf,ekf-fej,isam2-fast,dead_reckoning", "slow", victoria_park),
    Source("plaza", "python -m scripts.plaza_range_model (fgslam import plazaN --noise OTHER.json; fgslam run "
           "--estimators ekf,isam2,isam2-fast,dead_reckoning)", "long", plaza_range_model),
    Source("window-arena", "python -m scripts.bench_window arena-laps:1:40 --window 200 500 (without the times)",
           "slow", window_arena),
    Source("live-replay", "fgslam run tests/data/live-sim/octagon.jsonl --estimators ekf,isam2 (NEES)", "cheap",
           live_replay),
    Source("exact-models-nees", "python -m scripts.live_nees --simulate 30", "slow", exact_models_nees),
    Source("live-laps", "python -m scripts.live_nees --record 10", "long", live_laps),
    Source("live-band", "fgslam.consistency.run_nees_band(tests/data/live-sim/octagon.jsonl, ekf), stated sigma "
           "x 1, 0.4, 0.5, 0.7", "slow", live_band),
    Source("octagon-outliers-ekf-no-gate", "fgslam sim arena-octagon --seed 1 --outliers 0.1 "
           "--outlier-mode add; EkfSlam(known_id_gate_probability=None)", "cheap", ekf_without_gate),
    Source("mrclam6", "python -m scripts.bench_mrclam ../shared/data/mrclam/MRCLAM_Dataset6 --estimators "
           "ekf,ekf-fej,isam2,dead_reckoning", "slow",
           mrclam_dataset6, shared=MRCLAM6),
    Source("mrclam6-adaptive", "python -m scripts.mrclam_adaptive_noise ../shared/data/mrclam/MRCLAM_Dataset6 "
           "--open-loop --sim", "slow", mrclam_dataset6_adaptive, shared=MRCLAM6),
    Source("mrclam6-motor-lens", "python -m scripts.mrclam_motor_lens_tried ../shared/data/mrclam/MRCLAM_Dataset6",
           "cheap", mrclam_dataset6_motor_lens, shared=MRCLAM6),
    Source("mrclam6-camera", "python -m scripts.mrclam_camera_tried ../shared/data/mrclam/MRCLAM_Dataset6",
           "slow", mrclam_dataset6_camera, shared=MRCLAM6),
    Source("mrclam6-hidden", "python -m scripts.bench_association_mrclam ../shared/data/mrclam/MRCLAM_Dataset6 "
           "--estimators ekf,ekf-fej,isam2",
           "long", mrclam_dataset6_hidden, shared=MRCLAM6),
    Source("bench-octagon", "fgslam bench arena-octagon --runs 50 --jobs 2 --estimators ekf,ekf-fej,isam2", "long",
           monte_carlo_octagon),
    Source("sweep-octagon", "python -m scripts.seed_sweep arena-octagon --seeds 0-19 --jobs 2", "long",
           seed_sweep("arena-octagon", range(0, 20))),
    Source("sweep-grid200", "python -m scripts.seed_sweep grid --landmarks 200 --seeds 0-5 --jobs 2", "long",
           seed_sweep("grid", range(0, 6))),
    Source("seed004-measured", "python -m scripts.seed004_paths --seeds 1-20 --jobs 2", "long",
           seed004_paths("measured")),
    Source("seed004-nominal", "python -m scripts.seed004_paths --seeds 1-20 --jobs 2 --tag-noise nominal", "long",
           seed004_paths("nominal")),
    Source("seed001-association", "python -m scripts.seed001_association --spacings 0.25,0.5,0.75,1.0,1.5,2.0,3.0 "
           "--jobs 2", "long", seed001_association),
    Source("seed003-real", "python -m scripts.seed003_drives --data ../shared/data/seed003 (real drives)", "slow",
           seed003_drives(("0020", "0027", "0042"), shared=True), shared=SEED003),
    Source("seed003-sim", "python -m scripts.seed003_drives --seeds 1-10 (simulated drives)", "long",
           seed003_drives(range(1, 11), shared=False)),
    Source("stereo-pixel-covariance", "python -m scripts.stereo_pixel_covariance --seeds 1 2 3 4 5", "long",
           stereo_pixel_covariance),
]

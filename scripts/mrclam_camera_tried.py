"""MRCLAM: where a reading's error comes from — the place in the picture, per camera.

docs/datasets-mrclam-rosbag.md ("Consistency and accuracy: what was tried") quotes this
script's output. The product models the readings' error as white noise plus a Gauss–Markov
part in *time* (``correlated_share``, ``correlation_time_s``). Against Vicon this script asks
what the correlated part depends on, and what knowing it would be worth:

1. ``pairs``: the correlation of two readings' errors (range and bearing, each run's own
   scale and bias removed and divided by the fitted σ, as ``fgslam calibrate`` fits them;
   the model pooled over all robots, which only describes the data here), binned three ways:
   readings of one landmark by the time between them; readings of one landmark less than
   0.5 s apart, and 2–8 s apart, by how far the landmark moved in the picture (|Δ bearing|); and readings of
   *different* landmarks in the same run less than 30 s apart, by |Δ bearing|.
2. ``oracle``: each robot imported with the noise model fitted on the other four (as
   ``scripts/bench_mrclam.py``), then each reading corrected by a cubic in its bearing fitted
   to *its own run's* errors against Vicon (robust: refitted inside 5 robust σ) — a camera
   calibrated perfectly on the run it is scored on, which no product may do. Printed: the
   range and bearing RMS against Vicon before and after, and the ATE (anchored and
   SE(2)-aligned) and the NIS share inside the 95 % band of ``ekf`` and ``isam2`` on both
   logs: what a per-camera model of the picture's errors could buy at most.
3. ``ekf``: the product's EKF with its Gauss–Markov reading errors decaying with the
   landmark's move in the picture as well as with time, ``φ = exp(−Δt/τ − |Δb|/β)`` per
   component (β 0.6 rad for range and 0.035 rad for bearing: where the ``pairs``
   correlations fall to about half), on the same leave-one-out logs. Printed per robot: the
   ATE (anchored and aligned) and the share of NIS values inside the 95 % band, for the
   product's model and for the picture decay with the model's ρ and τ, and with ρ 0.7 and
   τ 40 s (the time decay left to the slow part).

Usage::

    .venv/bin/python -m scripts.mrclam_camera_tried ../shared/data/mrclam/MRCLAM_Dataset6 [pairs|oracle|ekf ...]

``pairs`` and ``ekf`` take seconds to a minute, ``oracle`` a few minutes.
"""

from __future__ import annotations

import os

from scripts.common import one_blas_thread, parse_folder_and_parts, write_json

one_blas_thread(force=False)

import math  # noqa: E402
import sys  # noqa: E402
from dataclasses import replace  # noqa: E402

import numpy as np  # noqa: E402

from scripts.bench_mrclam import ate_and_turn, leave_one_out, nis_inside, raw_logs, score_robot  # noqa: E402
from ekf import EkfSlam  # noqa: E402
from ekf.reading_error import reading_sigmas  # noqa: E402
from slamio.geometry import wrap_angle  # noqa: E402
from slamio.log import Observation, RunLog  # noqa: E402
from slamio.noise.dead_reckoning import turn_rate_radps  # noqa: E402
from slamio.noise.fit_truth import fit_noise_model, true_range_bearing  # noqa: E402
from slamio.noise.fitting import GATE_SIGMAS, mad_sigma, residuals_about_own_lines, truth_data  # noqa: E402

#: Bins of the time between two readings of one landmark (s).
TIME_BINS_S = (0.0, 0.5, 2.0, 8.0, 32.0, 64.0)
#: Bins of how far a landmark moved in the picture between two readings (|Δ bearing|, rad).
PICTURE_BINS_RAD = (0.0, 0.005, 0.02, 0.05, 0.1, 0.3, math.pi)
#: Readings of different landmarks are paired when less than this far apart in time (s).
CROSS_WINDOW_S = 30.0
#: The oracle's correction: a polynomial of this degree in the measured bearing.
ORACLE_DEGREE = 3
ESTIMATORS = ("ekf", "isam2")
#: The ``ekf`` part's picture scales β (rad) for range and bearing.
PICTURE_DECAY_RAD = (0.6, 0.035)
#: Its variants: name → (β or None for the product's decay in time alone, ρ, τ s; None keeps the model's).
EKF_VARIANTS = {
    "product (decay in time)": (None, None, None),
    "decay in time and picture": (PICTURE_DECAY_RAD, None, None),
    "decay in time and picture, ρ 0.7, τ 40 s": (PICTURE_DECAY_RAD, 0.7, 40.0),
}


# ----------------------------------------------------------------------------- pairs


def normalised_errors(raw: dict[int, RunLog]) -> dict[str, np.ndarray]:
    """Every reading with truth: its run, landmark, time, true bearing and (range, bearing)
    error over σ, about its run's own scale and bias (``slamio.noise.fit_truth``'s residuals)."""
    model = fit_noise_model(list(raw.values()))
    obs, odo = model.observation, model.odometry
    datas = [truth_data(log) for log in raw.values()]
    parts = [true_range_bearing(d, obs.camera_latency_s) for d in datas]
    rm, bm, r, b, t = (np.concatenate([p[j] for p in parts]) for j in range(5))
    landmark = np.unique(np.vstack([p[5] for p in parts]), axis=0, return_inverse=True)[1].ravel()
    run = np.concatenate([np.full(len(p[0]), j) for j, p in enumerate(parts)])
    omega = np.concatenate([odo.turn_scale * turn_rate_radps(d.chain, p[4] - odo.lag_s) for d, p in zip(datas, parts)])
    along = r * np.cos(b) if obs.range_is_depth else r
    res_r = residuals_about_own_lines(along, rm, run, (obs.range_scale, obs.range_bias_m))
    res_b = residuals_about_own_lines(b, bm, run, (obs.bearing_scale, obs.bearing_bias_rad))
    inlier = (np.abs(res_r) <= GATE_SIGMAS * mad_sigma(res_r)) & (np.abs(res_b) <= GATE_SIGMAS * mad_sigma(res_b))
    sigma_r = np.array([obs.sigma_range_m(float(v)) for v in r])
    sigma_b = np.array([obs.sigma_bearing_rad(float(w)) for w in omega])
    z = np.column_stack([res_r / sigma_r, res_b / sigma_b])
    return {"run": run[inlier], "landmark": landmark[inlier], "t": t[inlier], "b": b[inlier], "z": z[inlier]}


def _pairs(e: dict[str, np.ndarray], same_landmark: bool, max_dt_s: float) -> np.ndarray:
    """(Δt, |Δb|, z_a·z_b for range and bearing, z_a², z_b² for both) of every pair of
    readings in one run less than ``max_dt_s`` apart, of the same landmark or of different ones."""
    order = np.lexsort((e["t"], e["run"]))
    run, lm, t, b, z = (e[k][order] for k in ("run", "landmark", "t", "b", "z"))
    rows = []
    for shift in range(1, len(t)):
        dt = t[shift:] - t[:-shift]
        same_run = run[shift:] == run[:-shift]
        if not (same_run & (dt < max_dt_s)).any():
            break
        same = lm[shift:] == lm[:-shift]
        ok = same_run & (dt < max_dt_s) & (same if same_landmark else ~same)
        a = np.flatnonzero(ok)
        c = a + shift
        rows.append(np.column_stack([dt[ok], np.abs(wrap_angle(b[c] - b[a])), z[a] * z[c], z[a] ** 2, z[c] ** 2]))
    return np.vstack(rows) if rows else np.zeros((0, 8))


def binned(pairs: np.ndarray, column: int, edges, mask=None) -> list[dict]:
    """Correlation of the range and of the bearing errors per bin of ``pairs[:, column]``."""
    out = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        m = (pairs[:, column] >= lo) & (pairs[:, column] < hi)
        if mask is not None:
            m &= mask
        p = pairs[m]
        if len(p) < 30:
            continue
        corr = [float(p[:, 2 + j].sum() / math.sqrt(p[:, 4 + j].sum() * p[:, 6 + j].sum())) for j in range(2)]
        out.append({"low": lo, "high": hi, "pairs": int(len(p)), "range": corr[0], "bearing": corr[1]})
    return out


def pairs_report(raw: dict[int, RunLog]) -> dict:
    e = normalised_errors(raw)
    same = _pairs(e, True, TIME_BINS_S[-1])
    cross = _pairs(e, False, CROSS_WINDOW_S)
    result = {
        "by_time": binned(same, 0, TIME_BINS_S),
        "by_picture_within_0_5s": binned(same, 1, PICTURE_BINS_RAD, mask=same[:, 0] < 0.5),
        "by_picture_2_to_8s": binned(same, 1, PICTURE_BINS_RAD, mask=(same[:, 0] >= 2.0) & (same[:, 0] < 8.0)),
        "other_landmarks_by_picture": binned(cross, 1, PICTURE_BINS_RAD),
    }
    for name, rows, unit in (("one landmark, by time apart", result["by_time"], "s"),
                             ("one landmark < 0.5 s apart, by |Δ bearing|", result["by_picture_within_0_5s"], "rad"),
                             ("one landmark 2–8 s apart, by |Δ bearing|", result["by_picture_2_to_8s"], "rad"),
                             (f"other landmarks < {CROSS_WINDOW_S:g} s apart, by |Δ bearing|",
                              result["other_landmarks_by_picture"], "rad")):
        print(f"correlation of two readings' errors (range, bearing): {name}")
        for row in rows:
            print(f"  {row['low']:g}–{row['high']:.3g} {unit}: {row['range']:+.2f}, {row['bearing']:+.2f} "
                  f"({row['pairs']} pairs)")
    return result


# ----------------------------------------------------------------------------- oracle


def picture_errors(log: RunLog) -> np.ndarray:
    """(measured bearing, range error m, bearing error rad) of every reading against Vicon."""
    surveyed = {i: (t.x_m, t.y_m) for i, t in log.truth_landmarks().items()}
    rows = []
    for step in log.steps():
        if step.truth is None:
            continue
        for o in step.observations:
            if o.landmark_id not in surveyed or o.bearing_rad is None:
                continue
            dx, dy = surveyed[o.landmark_id][0] - step.truth.x_m, surveyed[o.landmark_id][1] - step.truth.y_m
            rows.append((o.bearing_rad, o.range_m - math.hypot(dx, dy),
                         float(wrap_angle(o.bearing_rad - (math.atan2(dy, dx) - step.truth.theta_rad)))))
    return np.array(rows).reshape(-1, 3)


def robust_polyfit(x: np.ndarray, y: np.ndarray, degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares polynomial, refitted inside 5 robust σ of its residuals: (coefficients, inliers)."""
    keep = np.ones(len(x), bool)
    for _ in range(4):
        coef = np.polyfit(x[keep], y[keep], degree)
        res = y - np.polyval(coef, x)
        keep = np.abs(res - np.median(res[keep])) <= GATE_SIGMAS * max(mad_sigma(res[keep]), 1e-12)
    return coef, keep


def corrected(log: RunLog, range_coef: np.ndarray, bearing_coef: np.ndarray) -> RunLog:
    """The log with every reading's picture error (the polynomials in its bearing) taken out."""
    records = []
    for r in log.records:
        if isinstance(r, Observation) and r.bearing_rad is not None:
            r = replace(r, range_m=r.range_m - float(np.polyval(range_coef, r.bearing_rad)),
                        bearing_rad=float(wrap_angle(r.bearing_rad - np.polyval(bearing_coef, r.bearing_rad))))
        records.append(r)
    return RunLog(log.path + " (picture errors removed)", log.header, tuple(records))


def oracle_report(folder: str, raw: dict[int, RunLog]) -> dict:
    result = {}
    for k in raw:
        header, records, _ = leave_one_out(folder, k, raw)
        log = RunLog(f"robot{k}", header, tuple(records))
        err = picture_errors(log)
        range_coef, keep_r = robust_polyfit(err[:, 0], err[:, 1], ORACLE_DEGREE)
        bearing_coef, keep_b = robust_polyfit(err[:, 0], err[:, 2], ORACLE_DEGREE)
        keep = keep_r & keep_b
        after_r = err[:, 1] - np.polyval(range_coef, err[:, 0])
        after_b = err[:, 2] - np.polyval(bearing_coef, err[:, 0])
        row = {"range_rms_m": [float(np.sqrt(np.mean(v[keep] ** 2))) for v in (err[:, 1], after_r)],
               "bearing_rms_rad": [float(np.sqrt(np.mean(v[keep] ** 2))) for v in (err[:, 2], after_b)]}
        for variant, scored in (("model", log), ("oracle", corrected(log, range_coef, bearing_coef))):
            runs = score_robot(scored, list(ESTIMATORS))
            row[variant] = {n: {"ate_m": runs[n]["ate_final_m"], "ate_aligned_m": runs[n]["ate_final_aligned_m"],
                                "nis_inside": runs[n]["nis_inside"]} for n in ESTIMATORS}
        result[k] = row
        print(f"robot {k}: range RMS {row['range_rms_m'][0]:.3f} → {row['range_rms_m'][1]:.3f} m, bearing RMS "
              f"{row['bearing_rms_rad'][0]:.4f} → {row['bearing_rms_rad'][1]:.4f} rad; "
              + "; ".join(f"{n} ATE {row['model'][n]['ate_m']:.3f} → {row['oracle'][n]['ate_m']:.3f} m, aligned "
                          f"{row['model'][n]['ate_aligned_m']:.3f} → {row['oracle'][n]['ate_aligned_m']:.3f} m, NIS "
                          f"{100 * row['model'][n]['nis_inside']:.1f} → {100 * row['oracle'][n]['nis_inside']:.1f} %"
                          for n in ESTIMATORS), flush=True)
    robots = list(result)
    result["median"] = {}
    for n in ESTIMATORS:
        med = {v: {m: float(np.median([result[k][v][n][m] for k in robots])) for m in ("ate_m", "ate_aligned_m", "nis_inside")}
               for v in ("model", "oracle")}
        result["median"][n] = med
        print(f"median {n}: ATE {med['model']['ate_m']:.3f} → {med['oracle']['ate_m']:.3f} m, aligned "
              f"{med['model']['ate_aligned_m']:.3f} → {med['oracle']['ate_aligned_m']:.3f} m, NIS "
              f"{100 * med['model']['nis_inside']:.1f} → {100 * med['oracle']['nis_inside']:.1f} %")
    return result


# ----------------------------------------------------------------------------- ekf


class PictureDecayEkf(EkfSlam):
    """The product's EKF whose reading errors also decay with the landmark's move in the
    picture: ``φ = exp(−Δt/τ − |Δb|/β)`` per component (Δb between this reading's bearing and
    the landmark's previous one)."""

    def __init__(self, header, picture_rad, share=None, time_s=None):
        super().__init__(header)
        self.picture_rad = picture_rad
        self._error_bearing: dict[int, float] = {}
        if self.reading_error is not None:
            self.reading_error = replace(self.reading_error, share=share or self.reading_error.share,
                                         time_s=time_s or self.reading_error.time_s)

    def _error_transition(self, key, observation):
        dt = max(observation.stamp_s - self._error_time[key], 0.0)
        db = abs(float(wrap_angle(observation.bearing_rad - self._error_bearing[key])))
        phi = np.exp(-dt / self.reading_error.time_s - db / np.asarray(self.picture_rad))
        before, now = self._error_sigma[key], reading_sigmas(observation)
        return phi * now / before, self.reading_error.share * now**2 * (1.0 - phi**2)

    def _add_reading_error(self, key, observation, G_measurement):
        super()._add_reading_error(key, observation, G_measurement)
        self._error_bearing[key] = observation.bearing_rad

    def _decay_reading_error(self, key, observation):
        super()._decay_reading_error(key, observation)
        self._error_bearing[key] = observation.bearing_rad


def ekf_scores(log: RunLog, picture_rad, share, time_s) -> dict:
    """ATE (anchored, aligned) and NIS share inside the 95 % band of one EKF variant on ``log``."""
    steps = log.steps()
    ekf = EkfSlam(log.header) if picture_rad is None else PictureDecayEkf(log.header, picture_rad, share, time_s)
    nis = []
    for step in steps:
        nis += [v for v in ekf.predicted_nis(step) if v is not None]
        ekf.step(step)
    ekf.finish()
    mask = np.array([s.truth is not None for s in steps])
    truth_xy = np.array([[s.truth.x_m, s.truth.y_m] if s.truth else [np.nan, np.nan] for s in steps])
    ate, aligned, _ = ate_and_turn(ekf.trajectory(), truth_xy, mask)
    return {"ate_m": ate, "ate_aligned_m": aligned, "nis_inside": nis_inside(nis)}


def ekf_report(folder: str, raw: dict[int, RunLog]) -> dict:
    result: dict = {}
    for k in raw:
        header, records, _ = leave_one_out(folder, k, raw)
        log = RunLog(f"robot{k}", header, tuple(records))
        result[k] = {name: ekf_scores(log, *variant) for name, variant in EKF_VARIANTS.items()}
        print(f"robot {k}: " + "; ".join(f"{name} ATE {v['ate_m']:.3f} aligned {v['ate_aligned_m']:.3f} m, NIS "
                                         f"{100 * v['nis_inside']:.1f} %" for name, v in result[k].items()), flush=True)
    robots = list(result)
    result["median"] = {name: {m: float(np.median([result[k][name][m] for k in robots]))
                               for m in ("ate_m", "ate_aligned_m", "nis_inside")} for name in EKF_VARIANTS}
    for name, v in result["median"].items():
        print(f"median, {name}: ATE {v['ate_m']:.3f} aligned {v['ate_aligned_m']:.3f} m, NIS {100 * v['nis_inside']:.1f} %")
    return result


def main(argv=None) -> int:
    parser, args, parts = parse_folder_and_parts(__doc__, argv, ("pairs", "oracle", "ekf"), "all three",
                                                 "choose from pairs, oracle and ekf")
    if not os.path.exists(os.path.join(args.folder, "Robot1_Odometry.dat")):
        parser.error(f"{args.folder}: no Robot1_Odometry.dat here; give an MRCLAM dataset folder")
    raw = raw_logs(args.folder)
    result = {}
    if "pairs" in parts:
        result["pairs"] = pairs_report(raw)
    if "oracle" in parts:
        result["oracle"] = oracle_report(args.folder, raw)
    if "ekf" in parts:
        result["ekf"] = ekf_report(args.folder, raw)
    write_json(args.json, result)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""MRCLAM: can the EKF learn its own run's noise scales from its innovations? (NIS goal 93–97 %)

Innovation-based adaptive estimation (Mehra 1970; the variational-Bayes form of Särkkä and
Nummenmaa 2009): the EKF's innovation ``ν = z − h(x̂)`` has covariance ``S = A + B``, where
``A = H Σ Hᵀ`` is the state's part (the pose, the landmark and the landmark's Gauss–Markov
reading error, all of which the filter carries) and ``B`` the reading's white noise. Three
variance scales, each with an inverse-gamma prior of mean 1 (the calibrated model, fitted on
the *other* robots) and exponential forgetting, are estimated from the innovations seen so
far and applied to what comes next:

* ``λ_r`` on the camera's range variance and ``λ_b`` on its bearing variance;
* ``λ_q`` on the odometry covariance.

Each innovation splits between the reading and the state by the conditional expectations of
a Gaussian (the EM / variational-Bayes step): ``E[w wᵀ | ν] = B − B S⁻¹ B + B S⁻¹ ν νᵀ S⁻¹ B``
for the reading's error ``w`` and the same with ``A`` for the state's part ``H δx``. With the
current scale ``λ`` inside ``B`` (or ``A``), ``λ·E[w_i²]/B_ii`` is one draw of the scale; the
inverse-gamma posterior ``IG(α, β)`` adds ½ to α and ½ of that to β per component, and
forgetting ``f`` pulls both back towards the prior ``IG(α₀, α₀)`` (memory ≈ 1/(1 − f)
readings). The estimate used is the posterior mean ``β/α``. Innovations outside the EKF's
validation gate (misread barcodes) are left out. Nothing here uses the truth at run time.

``--open-loop`` adds oracles that bound what any scale can do for the share of NIS values
inside the 95 % band: on the product EKF's own innovations, the best *constant* per-run
scales of ``A`` and ``B`` (chosen after the fact, per robot) and a scale taken from the
innovations of a window around each reading (it sees the future); the readings against
Vicon (every pose known) with each run's own variance scales; the closed-loop EKF with
each camera's variances set to its own against Vicon (as if calibrated on another run of
the same robot); and the product EKF's NIS split by the time since the same landmark's
previous reading (where the misses below the band are).

Usage::

    .venv/bin/python -m scripts.mrclam_adaptive_noise ../shared/data/mrclam/MRCLAM_Dataset6 [--open-loop] [--sim] [--json FILE]

Prints, per robot (noise fitted on the other four) and as medians: NIS share inside the
95 % χ²(2) band, median NIS (χ²(2) has 1.39), ATE against Vicon anchored and SE(2)-aligned.
``--sim`` also runs the simulated ``arena-octagon`` log (``data/arena_octagon.jsonl``),
whose noise is exact, to see that the adaptation leaves a consistent filter consistent.
"""

from __future__ import annotations

from scripts.common import one_blas_thread

one_blas_thread()

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy.stats import chi2  # noqa: E402

from scripts.bench_mrclam import ate_pair_m, leave_one_out, nis_inside, raw_logs  # noqa: E402
from ekf.models import motion_jacobians, predict_pose, range_bearing, range_bearing_jacobians  # noqa: E402
from ekf.observation import measurement_covariance  # noqa: E402
from ekf.slam import EkfSlam  # noqa: E402
from slamio.geometry import wrap_angle  # noqa: E402
from slamio.log import RunLog, Step, read_log  # noqa: E402
from slamio.noise.dead_reckoning import turn_rate_radps  # noqa: E402
from slamio.noise.fit_truth import true_range_bearing  # noqa: E402
from slamio.noise.fitting import line_fit, truth_data  # noqa: E402
from scripts.common import DATA  # noqa: E402

LOW, HIGH = chi2.ppf(0.025, 2), chi2.ppf(0.975, 2)


# ----------------------------------------------------------------------------- innovations


class InnovationEkf(EkfSlam):
    """The product's EKF, which also says how each predicted innovation's covariance splits."""

    def innovation_parts(self, step: Step) -> list[tuple | None]:
        """For each observation of ``step`` (before it is applied, as ``predicted_nis``):
        ``(ν, S, A, B)`` with ``S = A + B``, ``A = H Σ Hᵀ`` the state's part (pose, landmark
        and, with a ``correlated_share``, the landmark's Gauss–Markov reading error) and ``B``
        the reading's white noise; None for an observation without a mapped landmark."""
        pose, P_rr, F = self._mean[:3].copy(), self._cov[:3, :3].copy(), np.eye(3)
        if step.odometry is not None:
            o = step.odometry
            increment = (o.dx_m, o.dy_m, o.dtheta_rad)
            F, F_increment = motion_jacobians(pose, increment)
            P_rr = F @ P_rr @ F.T + F_increment @ np.asarray(o.covariance, float) @ F_increment.T
            pose = predict_pose(pose, increment)
        out: list[tuple | None] = []
        for ob in step.observations:
            key = ob.landmark_id
            if key is None or key not in self._slot or ob.range_only:
                out.append(None)
                continue
            i = self._slot[key]
            rows = [i, i + 1]
            scale, added = np.ones(0), np.zeros(0)
            if key in self._error_index:
                j = self._error_index[key]
                rows += [j, j + 1]
                scale, added = self._error_transition(key, ob)
            m = 3 + len(rows)
            joint = np.empty((m, m))
            joint[:3, :3] = P_rr
            joint[:3, 3:] = F @ self._cov[:3, rows]
            joint[3:, :3] = joint[:3, 3:].T
            joint[3:, 3:] = self._cov[np.ix_(rows, rows)]
            decay = np.r_[np.ones(5), scale]
            joint = joint * np.outer(decay, decay) + np.diag(np.r_[np.zeros(5), added])
            predicted_range, predicted_bearing = range_bearing(pose, self._mean[i : i + 2])
            error = scale * self._mean[rows[2:]] if len(rows) > 2 else np.zeros(2)
            nu = np.array([ob.range_m - predicted_range - error[0],
                           wrap_angle(ob.bearing_rad - predicted_bearing - error[1])])
            H_pose, H_landmark = range_bearing_jacobians(pose, self._mean[i : i + 2])
            H = np.hstack([H_pose, H_landmark] + ([np.eye(2)] if len(rows) > 2 else []))
            white = measurement_covariance(ob) * (1.0 - self.reading_error.share if len(rows) > 2 else 1.0)
            A = H @ joint @ H.T
            out.append((nu, A + white, A, white))
        return out


# ----------------------------------------------------------------------------- the scale estimate


@dataclasses.dataclass
class ForgettingScale:
    """Inverse-gamma estimate of a variance scale with exponential forgetting.

    Prior ``IG(α₀, α₀)`` (mean ≈ 1: the calibrated model). Each draw ``s`` of the scale
    (one degree of freedom) does ``α ← f·α + (1 − f)·α₀ + ½``, ``β ← f·β + (1 − f)·α₀ + ½·s``;
    the estimate is ``β/α``. For draws whose mean is c, the estimate tends to
    ``(2(1 − f)α₀ + c)/(2(1 − f)α₀ + 1)`` (c itself with no forgetting)."""

    prior_weight: float = 3.0
    forgetting: float = 0.95
    alpha: float = dataclasses.field(init=False)
    beta: float = dataclasses.field(init=False)

    def __post_init__(self) -> None:
        self.alpha = self.beta = self.prior_weight

    @property
    def value(self) -> float:
        return self.beta / self.alpha

    def add(self, draw: float) -> None:
        f, a0 = self.forgetting, self.prior_weight
        self.alpha = f * self.alpha + (1.0 - f) * a0 + 0.5
        self.beta = f * self.beta + (1.0 - f) * a0 + 0.5 * draw


def conditional_second_moment(part: np.ndarray, S: np.ndarray, nu: np.ndarray) -> np.ndarray:
    """``E[x xᵀ | ν]`` for ``ν = x + y``, x ~ N(0, part), y independent, ``cov ν = S``."""
    gain = part @ np.linalg.inv(S)
    mean = gain @ nu
    return part - gain @ part + np.outer(mean, mean)


class AdaptiveNoiseEkf:
    """``InnovationEkf`` whose range, bearing and odometry variances are scaled by estimates
    learned from its own innovations (module docstring). ``adapt`` picks which scales move:
    any of ``"range"``, ``"bearing"``, ``"odometry"``."""

    def __init__(self, header, *, adapt=("range", "bearing", "odometry"), prior_weight=3.0, forgetting=0.95,
                 fixed=None):
        self.ekf = InnovationEkf(header)
        self.adapt = set(adapt)
        self.fixed = dict(fixed or {})  # scales that are not adapted but set (an oracle's)
        self.scales = {name: ForgettingScale(prior_weight, forgetting) for name in ("range", "bearing", "odometry")}
        self.gate = chi2.ppf(0.9999, 2)
        self.history: list[tuple[float, ...]] = []

    def value(self, name: str) -> float:
        """The scale in force: the estimate when ``name`` adapts, else the fixed one (1 by default)."""
        return self.scales[name].value if name in self.adapt else self.fixed.get(name, 1.0)

    def scaled(self, step: Step) -> Step:
        lr, lb, lq = (self.value(n) for n in ("range", "bearing", "odometry"))
        odometry = step.odometry
        if odometry is not None and lq != 1.0:
            covariance = tuple(tuple(lq * v for v in row) for row in odometry.covariance)
            odometry = dataclasses.replace(odometry, covariance=covariance)
        observations = tuple(
            ob if ob.range_only else dataclasses.replace(
                ob, sigma_range_m=ob.sigma_range_m * math.sqrt(lr), sigma_bearing_rad=ob.sigma_bearing_rad * math.sqrt(lb))
            for ob in step.observations
        )
        return dataclasses.replace(step, odometry=odometry, observations=observations)

    def step(self, step: Step) -> list[float | None]:
        """Apply one step; returns the NIS of each observation against the prediction (with
        the scales in force before the step), as ``predicted_nis`` does."""
        step = self.scaled(step)
        parts = self.ekf.innovation_parts(step)
        nis = [None if p is None else float(p[0] @ np.linalg.solve(p[1], p[0])) for p in parts]
        self.ekf.step(step)
        for p, d2 in zip(parts, nis):
            if p is None or d2 > self.gate:
                continue
            nu, S, A, B = p
            reading = conditional_second_moment(B, S, nu)
            state = conditional_second_moment(A, S, nu)
            if "range" in self.adapt:
                self.scales["range"].add(self.scales["range"].value * reading[0, 0] / B[0, 0])
            if "bearing" in self.adapt:
                self.scales["bearing"].add(self.scales["bearing"].value * reading[1, 1] / B[1, 1])
            if "odometry" in self.adapt:  # two degrees of freedom: two draws of tr(A⁻¹E[xxᵀ])/2
                draw = self.scales["odometry"].value * float(np.trace(np.linalg.solve(A, state))) / 2.0
                self.scales["odometry"].add(draw)
                self.scales["odometry"].add(draw)
        self.history.append(tuple(self.value(n) for n in ("range", "bearing", "odometry")))
        return nis


def run_adaptive(log: RunLog, **kwargs) -> dict:
    """Run :class:`AdaptiveNoiseEkf` (no ``adapt``: the plain product EKF) over a log and score it."""
    f = AdaptiveNoiseEkf(log.header, **kwargs)
    nis, track, truth = [], [], []
    for s in log.steps():
        values = f.step(s)
        if s.truth is not None:
            nis += [v for v in values if v is not None]
        track.append(f.ekf.current_pose())
        truth.append([s.truth.x_m, s.truth.y_m] if s.truth else [np.nan, np.nan])
    track, truth = np.array(track), np.array(truth)
    mask = np.isfinite(truth[:, 0])
    anchored, aligned = ate_pair_m(track, truth, mask)
    scales = np.array(f.history)
    return {"nis_inside": nis_inside(nis), "nis_median": float(np.median(nis)), "ate_m": anchored,
            "ate_aligned_m": aligned, "scale_medians": np.median(scales, axis=0)}


# ----------------------------------------------------------------------------- open-loop bounds


def share_in_band(z: np.ndarray, range_scale: float, bearing_scale: float) -> float:
    """Share of ``z_r²/range_scale + z_b²/bearing_scale`` inside the 95 % χ²(2) band."""
    d2 = z[:, 0] ** 2 / range_scale + z[:, 1] ** 2 / bearing_scale
    return float(np.mean((d2 >= LOW) & (d2 <= HIGH)))


def reading_z(raw: RunLog, model) -> np.ndarray:
    """(n, 2): each reading's range and bearing error against Vicon at the picture time, less
    the run's own scale and bias (a line fitted to the run), over ``model``'s σ."""
    obs, odometry = model.observation, model.odometry
    data = truth_data(raw)
    rm, bm, r, b, t, _ = true_range_bearing(data, obs.camera_latency_s)
    omega = odometry.turn_scale * turn_rate_radps(data.chain, t - odometry.lag_s)
    along = r * np.cos(b) if obs.range_is_depth else r
    sigma_r = np.array([obs.sigma_range_m(float(v)) for v in r])
    sigma_b = np.array([obs.sigma_bearing_rad(float(w)) for w in omega])
    return np.column_stack([line_fit(along, rm)[2] / sigma_r, line_fit(b, bm)[2] / sigma_b])


def reading_ceiling(raws: dict[int, RunLog], models: dict) -> dict[int, tuple[float, ...]]:
    """Per robot, readings against Vicon (no estimator: every pose known; each run's own
    scale and bias removed, :func:`reading_z`): ``(share with the model's σ,
    best share with the run's own variance scales, that range scale, that bearing scale,
    mean z_r², mean z_b²)``, the scales searched on a log grid 0.1–10 (an oracle: chosen
    after the fact), the means over the readings within 5σ (the run's variance over the
    model's: what an adaptive scale should find)."""
    grid = np.exp(np.linspace(math.log(0.1), math.log(10.0), 41))
    out = {}
    for k, raw in raws.items():
        z = reading_z(raw, models[k])
        best = max((share_in_band(z, a, c), a, c) for a in grid for c in grid)
        inlier = np.all(np.abs(z) <= 5.0, axis=1)
        out[k] = (share_in_band(z, 1.0, 1.0), *best, *np.mean(z[inlier] ** 2, axis=0))
    return out


def innovation_bounds(log: RunLog) -> dict:
    """Open-loop oracles on the product EKF's own innovations of one log (nothing fed back):
    the share in band as run, with the best constant scales of the state's part ``A`` and
    the reading's part ``B`` (chosen after the fact on a grid), and with a scale taken from
    the innovations of a window around each reading (itself excluded; it sees the future)."""
    f = InnovationEkf(log.header)
    rows, times = [], []
    for s in log.steps():
        if s.truth is not None:
            found = [p for p in f.innovation_parts(s) if p is not None]
            rows += found
            times += [s.stamp_s] * len(found)
        f.step(s)
    nu = np.array([p[0] for p in rows])
    A, B = np.array([p[2] for p in rows]), np.array([p[3] for p in rows])
    grid = np.exp(np.linspace(math.log(0.1), math.log(10.0), 21))
    best = max((nis_inside(np.einsum("ni,nij,nj->n", nu, np.linalg.inv(mu * A + lam * B), nu)), mu, lam)
               for mu in grid for lam in grid)
    nis = np.einsum("ni,nij,nj->n", nu, np.linalg.inv(A + B), nu)
    t = np.array(times)
    centred = {}
    for half_s in (0.5, 1.0, 2.0):  # the window's mean NIS/2, with one prior draw of 1
        c = np.empty_like(nis)
        for i in range(len(nis)):
            near = np.abs(t - t[i]) <= half_s
            near[i] = False
            c[i] = (1.0 + nis[near].sum() / 2.0) / (1.0 + near.sum())
        centred[half_s] = nis_inside(nis / c)
    return {"as_run": nis_inside(nis), "best_constant": best[0], "state_scale": float(best[1]), "reading_scale": float(best[2]),
            "centred": centred}


def nis_by_revisit(logs: dict[int, RunLog]) -> dict[str, dict]:
    """The product EKF's NIS (all robots pooled) split by the time since the same landmark's
    previous reading: share below / inside / above the 95 % band and the median."""
    bins = {"< 0.5 s": (0.0, 0.5), "0.5-2 s": (0.5, 2.0), "2-10 s": (2.0, 10.0), ">= 10 s": (10.0, math.inf)}
    values: list[tuple[float, float]] = []
    for log in logs.values():
        f, last = InnovationEkf(log.header), {}
        for s in log.steps():
            for ob, p in zip(s.observations, f.innovation_parts(s)):
                if p is not None and s.truth is not None:
                    values.append((float(p[0] @ np.linalg.solve(p[1], p[0])), s.stamp_s - last[ob.landmark_id]))
                if ob.landmark_id is not None:
                    last[ob.landmark_id] = s.stamp_s
            f.step(s)
    nis, gap = np.array(values).T
    out = {}
    for name, (a, b) in bins.items():
        v = nis[(gap >= a) & (gap < b)]
        out[name] = {"count": int(len(v)), "below": float(np.mean(v < LOW)), "inside": float(np.mean((v >= LOW) & (v <= HIGH))),
                     "above": float(np.mean(v > HIGH)), "median": float(np.median(v))}
    return out


def open_loop_bounds(logs: dict[int, RunLog], raws: dict[int, RunLog], models: dict) -> dict:
    """Print and return the readings' ceiling and the innovations' oracles, per robot."""
    print("## readings against Vicon, every pose known: share in band with the model's sigma; "
          "best share with the run's own variance scales (range, bearing)")
    ceiling = reading_ceiling(raws, models)
    for k, (model_share, best, a, c, vr, vb) in ceiling.items():
        print(f"robot {k}: {model_share:.3f}; {best:.3f} (x{a:.2f}, x{c:.2f}); variance over the model's "
              f"within 5 sigma: range {vr:.2f}, bearing {vb:.2f}")
    print("## open loop: the product EKF's innovations rescaled after the fact")
    bounds = {}
    for k, log in logs.items():
        b = bounds[k] = innovation_bounds(log)
        print(f"robot {k}: as run {b['as_run']:.3f}; best constant scales (state x{b['state_scale']:.2f}, reading "
              f"x{b['reading_scale']:.2f}) {b['best_constant']:.3f}; centred-window scale ±0.5 / ±1 / ±2 s: "
              + " / ".join(f"{v:.3f}" for v in b["centred"].values()))
    print("## the product EKF's NIS by the time since the landmark's previous reading (all robots): "
          "count, below / inside / above the band, median")
    revisit = nis_by_revisit(logs)
    for name, r in revisit.items():
        print(f"{name}: {r['count']}, {r['below']:.3f} / {r['inside']:.3f} / {r['above']:.3f}, {r['median']:.2f}")
    names = ("model", "best", "range_scale", "bearing_scale", "range_variance_ratio", "bearing_variance_ratio")
    return {"readings": {k: dict(zip(names, map(float, v))) for k, v in ceiling.items()},
            "innovations": bounds, "revisit": revisit}


# ----------------------------------------------------------------------------- main

VARIANTS = {
    "product EKF (no adaptation)": {"adapt": ()},
    "range + bearing scales, f 0.95": {"adapt": ("range", "bearing")},
    "range + bearing scales, f 0.999 (a run-long camera scale)": {"adapt": ("range", "bearing"), "forgetting": 0.999},
    "odometry scale, f 0.95": {"adapt": ("odometry",)},
    "all three, f 0.8": {"forgetting": 0.8},
    "all three, f 0.95": {},
    "all three, f 0.99": {"forgetting": 0.99},
}

#: With ``--open-loop``: each robot's camera σ scaled by its own readings' variance against
#: Vicon (an oracle, as if calibrated on another run of the same robot), nothing adapted.
ORACLE = "camera variances set to the run's own against Vicon (oracle)"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("folder", help="an MRCLAM_DatasetK folder")
    parser.add_argument("--open-loop", action="store_true", help="also the open-loop oracle bounds")
    parser.add_argument("--sim", action="store_true", help="also data/arena_octagon.jsonl (simulated, exact noise)")
    parser.add_argument("--json", default=None, metavar="FILE", help="write every figure here")
    args = parser.parse_args(argv)
    raw = raw_logs(args.folder)
    logs, models = {}, {}
    for k in raw:
        header, records, models[k] = leave_one_out(args.folder, k, raw)
        logs[k] = RunLog(f"robot{k}", header, tuple(records))
    out: dict = {"variants": {}}
    variants = {name: {k: kwargs for k in logs} for name, kwargs in VARIANTS.items()}
    if args.open_loop:
        out["open_loop"] = open_loop_bounds(logs, raw, models)
        readings = out["open_loop"]["readings"]
        variants[ORACLE] = {k: {"adapt": (), "fixed": {"range": readings[k]["range_variance_ratio"],
                                                       "bearing": readings[k]["bearing_variance_ratio"]}} for k in logs}
    print("## closed loop: NIS in band / median NIS / ATE anchored / ATE aligned (m); scale medians (range, bearing, odometry)")
    sim = read_log(str(DATA / "arena_octagon.jsonl")) if args.sim else None
    columns = ("nis_inside", "nis_median", "ate_m", "ate_aligned_m")
    for name, per_robot in variants.items():
        rows = {k: run_adaptive(log, **per_robot[k]) for k, log in logs.items()}
        kwargs = next(iter(per_robot.values()))
        cells = "; ".join(f"{k}: {r['nis_inside']:.3f}/{r['nis_median']:.2f}/{r['ate_m']:.3f}/{r['ate_aligned_m']:.3f} "
                          f"({', '.join(f'{v:.2f}' for v in r['scale_medians'])})" for k, r in rows.items())
        median = {c: float(np.median([r[c] for r in rows.values()])) for c in columns}
        print(f"{name}: {cells}")
        print("    median: " + " / ".join(f"{median[c]:.3f}" for c in columns))
        entry = out["variants"][name] = {"robots": {k: {c: r[c] for c in columns} | {"scale_medians": r["scale_medians"].tolist()}
                                                    for k, r in rows.items()}, "median": median}
        if sim is not None and name != ORACLE:
            r = run_adaptive(sim, **kwargs)
            entry["arena_octagon"] = {c: r[c] for c in ("nis_inside", "nis_median", "ate_m")}
            print(f"    arena-octagon (simulated): {r['nis_inside']:.3f} / {r['nis_median']:.2f} / {r['ate_m']:.4f}")
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1) + "\n")
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

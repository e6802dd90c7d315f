"""Why is the robust iSAM2's online estimate worse than without the DCS kernel on MRCLAM robot 1?

The question of issue 42 part 6 (docs/results-datasets.md, "Online iSAM2 against its final
estimate"): without the kernel robot 1's online ATE is 0.166 m against 0.215 m, and the
guess was that DCS down-weights correct readings of a young landmark at the estimate of the
time. Two measurements and the variants that separate the causes:

* ``--weights``: each reading's DCS weight where iSAM2 linearised it when it entered (the
  seed of its pose) and at the final estimate, counted by how many readings its landmark had
  before; and each waiting first sighting the confirmation dropped, with its ½‖whitened
  residual‖² at the estimate and at the truth.
* variants of the default ``isam2`` on the log's own header (the kernel as
  ``expected_outlier_kernel`` chooses it): ``base`` (as shipped); ``gaussian-weights`` (the
  robust mode with DCS's width at 1 000σ: every weight 1, the first-sighting confirmation
  kept); ``dcs-k5``, ``dcs-k8`` (DCS's k at 5σ, 8σ instead of 3.717σ);
  ``relinearise-on-entry`` (after each update, the pose and landmark of every new reading
  DCS down-weighted at its linearisation point are relinearised at once, the rest held by
  ``noRelinKeys``); ``no-confirm`` (first sightings enter at once, as without a kernel);
  ``wait-robust`` (once a landmark is confirmed, the other sightings that waited enter as
  ordinary readings under the kernel instead of being gated at 7σ and dropped);
  ``innovation-gate`` (they are gated once the landmark is in iSAM2, against the
  innovation covariance R + J Σ Jᵀ, Σ the iSAM2 marginals of their pose and the landmark,
  cross-covariance left out; ``½ d² ≤ PENDING_GATE``); ``corrector-gaussian`` (a reading the
  online correction used, i.e. whose NIS against the pose's predicted covariance was not a
  surprise, enters with its Gaussian factor, the others under the kernel), and that with the
  innovation gate.

Prints one line per log and variant: anchored / aligned ATE of the final and the online
estimate against the log's truth, and how many waiting sightings were dropped.

    PYTHONPATH=. .venv/bin/python -m scripts.experiments.online_kernel RUNS/robot1.jsonl:MODELS/self1.json \
        --variants base,gaussian-weights,no-confirm,wait-robust,innovation-gate [--weights]

``LOG:MODEL`` applies a noise model first (``fgslam calibrate LOG --without-truth --out
MODEL`` is what ``fgslam run LOG --noise self`` fits); a bare ``LOG`` runs as it is.
"""

from __future__ import annotations

from scripts.common import one_blas_thread

one_blas_thread()

import argparse  # noqa: E402
import math  # noqa: E402
import types  # noqa: E402

import gtsam  # noqa: E402
import numpy as np  # noqa: E402
from gtsam.symbol_shorthand import L, T, X  # noqa: E402

from fgslam.registry import expected_outlier_kernel  # noqa: E402
from fgslam.runner import run_estimator, truth_landmark_map, truth_trajectory  # noqa: E402
from fgslam.smoother import Isam2Smoother  # noqa: E402
from fgslam.smoother.factors import DEFAULT_ROBUST_K  # noqa: E402
from fgslam.smoother.pending import within_gate  # noqa: E402
from slamio.log import read_log  # noqa: E402
from slamio.noise.apply import apply_noise_model  # noqa: E402
from slamio.noise.model import load_noise_model  # noqa: E402

from scripts.bench_mrclam import ate_pair_m  # noqa: E402

VARIANTS = ("base", "gaussian-weights", "dcs-k5", "dcs-k8", "relinearise-on-entry", "no-confirm", "wait-robust",
            "innovation-gate", "corrector-gaussian", "corrector-gaussian+innovation-gate")
#: DCS's Φ = k² (whitened units): weight 1 for r² ≤ Φ, (2Φ/(Φ + r²))² beyond.
DCS_PHI = DEFAULT_ROBUST_K["dcs"] ** 2


def dcs_weight(r2: float) -> float:
    """DCS's weight of a reading whose squared whitened residual norm is ``r2``."""
    return 1.0 if r2 <= DCS_PHI else (2.0 * DCS_PHI / (DCS_PHI + r2)) ** 2


def innovation_half_d2(entry, pose, landmark, isam) -> float:
    """½ rᵀ S⁻¹ r of a reading at ``pose`` and ``landmark``, whitened, with
    S = I + A Σ Aᵀ: A the whitened Jacobian, Σ the iSAM2 marginals of its two variables
    (block-diagonal: their cross-covariance left out, which makes S larger)."""
    values = gtsam.Values()
    values.insert(X(entry.pose_index), pose)
    values.insert(entry.key, landmark)
    linear = entry.gate_factor.linearize(values)
    A, b = linear.jacobian()
    blocks = [isam.marginalCovariance(key) for key in linear.keys()]
    sigma = np.zeros((A.shape[1], A.shape[1]))
    i = 0
    for block in blocks:
        d = block.shape[0]
        sigma[i:i + d, i:i + d] = block
        i += d
    S = np.eye(len(b)) + A @ sigma @ A.T
    return 0.5 * float(b @ np.linalg.solve(S, b))


def confirm_all(self, fresh, known):
    """``confirm_first_sightings`` with every other waiting sighting entering with the pair."""
    accepted, confirmed_now = [], set()
    for e in fresh:
        if e.landmark_id in known or e.landmark_id in confirmed_now:
            accepted.append(e)
            continue
        waiting = self.unconfirmed.setdefault(e.landmark_id, [])
        match = next((w for w in reversed(waiting) if within_gate(e, e.seed_pose, w.landmark_guess, self.gate)), None)
        if match is None:
            waiting.append(e)
            if len(waiting) > self.max_unconfirmed:
                waiting.pop(0)
                self.rejected_first_sightings += 1
            continue
        accepted += [w for w in waiting if w is not match] + [match, e]
        del self.unconfirmed[e.landmark_id]
        confirmed_now.add(e.landmark_id)
    return accepted


def make_screen(innovation: bool, log_drop):
    """A ``PendingObservations.screen`` that logs each drop (``log_drop(entry, pose,
    landmark)``) and, with ``innovation``, waits until the landmark is in iSAM2 and gates
    against the innovation covariance where the plain gate fails."""
    def screen(self, fresh, isam, landmarks):
        retry, wait = [], []
        for e in self.withheld:
            if e.attempts > self.max_retries:
                self.dropped += 1
                continue
            if e.landmark_id in landmarks.known:
                tag = e.landmark_id in landmarks.tag_ids
                landmark = (isam.calculateEstimatePose2(T(e.landmark_id)) if tag
                            else isam.calculateEstimatePoint2(L(e.landmark_id)))
            else:
                seen_now = [o for o in fresh if o.landmark_id == e.landmark_id]
                if not seen_now or innovation:
                    wait.append(e)
                    continue
                landmark = seen_now[-1].landmark_guess
            in_isam = isam.valueExists(X(e.pose_index))
            pose = isam.calculateEstimatePose2(X(e.pose_index)) if in_isam else e.seed_pose
            if within_gate(e, pose, landmark, self.gate) or (
                    innovation and in_isam and innovation_half_d2(e, pose, landmark, isam) <= self.gate):
                retry.append(e)
            else:
                log_drop(e, pose, landmark)
                self.dropped += 1
        self.withheld = wait
        return retry
    return screen


class WeightProbe(Isam2Smoother):
    """The shipped smoother, noting each reading's residual where iSAM2 linearised it on entry."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.entered = []  # (entry, r² at its linearisation point, readings of its landmark before)
        self._count: dict[int, int] = {}

    def _update_with_recovery(self, core, core_values, entries):
        super()._update_with_recovery(core, core_values, entries)
        lin = self._isam.getLinearizationPoint()
        for e in entries:
            if e.key != L(e.landmark_id) or not lin.exists(e.key) or not lin.exists(X(e.pose_index)):
                continue
            n = self._count.get(e.landmark_id, 0)
            self._count[e.landmark_id] = n + 1
            self.entered.append((e, 2.0 * e.gate_factor.error(lin), n))


class RelineariseOnEntry(WeightProbe):
    """After each update, relinearise the variables of the new readings DCS down-weighted
    where they were linearised (their pose's seed), so their weight is taken at the estimate."""

    def _update_with_recovery(self, core, core_values, entries):
        seen = len(self.entered)
        super()._update_with_recovery(core, core_values, entries)
        keys = set()
        for e, r2, _ in self.entered[seen:]:
            if r2 > DCS_PHI:
                keys.update((X(e.pose_index), e.key))
        if self._robust is None or not keys:
            return
        params = gtsam.ISAM2UpdateParams()
        params.force_relinearize = True
        held = gtsam.KeyList()
        for key in self._isam.getLinearizationPoint().keys():
            if key not in keys:
                held.push_back(key)
        params.noRelinKeys = held
        self._isam.update(gtsam.NonlinearFactorGraph(), gtsam.Values(), params)


class CorrectorGaussian(WeightProbe):
    """Readings the online correction used (consistent with the pose's predicted covariance)
    enter with their Gaussian factor; the others keep the kernel."""

    def step(self, step):
        self._used_now = set()
        super().step(step)

    def _corrected(self, odo, observations):
        seed, used = super()._corrected(odo, observations)
        self._used_now = {u[0] for u in used}
        return seed, used

    def _add_observation(self, k, seed, obs):
        n = len(self._held.entries)
        super()._add_observation(k, seed, obs)
        if len(self._held.entries) > n and obs.landmark_id in self._used_now:
            entry = self._held.entries[-1]
            entry.factor = entry.gate_factor


def smoother(variant: str, header, log_drop, weights: bool = False) -> Isam2Smoother:
    kernel = expected_outlier_kernel(header)
    k = {"gaussian-weights": 1000.0, "dcs-k5": 5.0, "dcs-k8": 8.0}.get(variant) if kernel else None
    cls = RelineariseOnEntry if variant == "relinearise-on-entry" else (WeightProbe if weights else Isam2Smoother)
    cls = CorrectorGaussian if variant.startswith("corrector-gaussian") else cls
    sm = cls(header, robust=kernel, robust_k=k)
    pending = sm._pending
    if variant == "no-confirm":
        pending.confirm_first_sightings = lambda fresh, known: fresh
    elif variant == "wait-robust":
        pending.confirm_first_sightings = types.MethodType(confirm_all, pending)
    pending.screen = types.MethodType(make_screen(variant.endswith("innovation-gate"), log_drop), pending)
    return sm


def half_r2_at_truth(entry, truth_poses, truth_landmarks) -> float:
    values = gtsam.Values()
    values.insert(X(entry.pose_index), gtsam.Pose2(*truth_poses[entry.pose_index]))
    values.insert(entry.key, np.array(truth_landmarks[entry.landmark_id], dtype=float))
    return entry.gate_factor.error(values)


def print_weights(sm: WeightProbe, final: gtsam.Values) -> None:
    r2_lin = np.array([r2 for _, r2, _ in sm.entered])
    r2_final = np.array([2.0 * e.gate_factor.error(final) for e, _, _ in sm.entered])
    before = np.array([n for _, _, n in sm.entered])
    low_lin, low_final = r2_lin > DCS_PHI, r2_final > DCS_PHI
    print(f"  readings {len(r2_lin)}: down-weighted where linearised on entry {low_lin.sum()} "
          f"(median weight {np.median([dcs_weight(v) for v in r2_lin[low_lin]]):.3f}), at the final estimate "
          f"{low_final.sum()}, on entry but not at the end {(low_lin & ~low_final).sum()}")
    for lo, hi in ((0, 3), (3, 10), (10, 30), (30, 10**9)):
        m = (before >= lo) & (before < hi)
        print(f"    landmark had {lo}-{hi if hi < 10**9 else '...'} readings before: {m.sum()} readings, "
              f"down-weighted on entry {(low_lin & m).sum()}, of them fine at the end {(low_lin & ~low_final & m).sum()}")


def run_one(path: str, model: str | None, variant: str, weights: bool) -> None:
    log = read_log(path)
    if model:
        log, _ = apply_noise_model(log, load_noise_model(model))
    steps = log.steps()
    truth, mask = truth_trajectory(steps)
    truth_landmarks = truth_landmark_map(log)[0]
    drops = []

    def log_drop(e, pose, landmark):
        values = gtsam.Values()
        values.insert(X(e.pose_index), pose)
        values.insert(e.key, landmark)
        at_truth = (half_r2_at_truth(e, truth, truth_landmarks)
                    if e.landmark_id in truth_landmarks and mask[e.pose_index] else math.nan)
        drops.append((e.landmark_id, e.pose_index, e.gate_factor.error(values), at_truth))

    sm = smoother(variant, log.header, log_drop, weights)
    run, _ = run_estimator(sm, steps, covariances=False)
    final, online = ate_pair_m(run.final, truth[:, :2], mask), ate_pair_m(run.online, truth[:, :2], mask)
    print(f"{path} {variant} (kernel {sm.robust}): final {final[0]:.3f} / {final[1]:.3f} m, "
          f"online {online[0]:.3f} / {online[1]:.3f} m, waiting sightings dropped {len(drops)}", flush=True)
    for lid, k, half_r2, at_truth in drops:
        print(f"    dropped: landmark {lid} seen from pose {k}, ½r² {half_r2:.1f} at the estimate, {at_truth:.1f} at the truth")
    if weights and isinstance(sm, WeightProbe) and sm.entered:
        print_weights(sm, sm._estimate_cache)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="+", help="LOG.jsonl or LOG.jsonl:MODEL.json")
    ap.add_argument("--variants", default="base", help=f"comma-separated, of {', '.join(VARIANTS)}")
    ap.add_argument("--weights", action="store_true", help="each reading's DCS weight on entry and at the end")
    args = ap.parse_args(argv)
    variants = args.variants.split(",")
    for v in variants:
        if v not in VARIANTS:
            raise SystemExit(f"unknown variant {v!r}")
    for spec in args.logs:
        path, _, model = spec.partition(".jsonl:")
        path = path if path.endswith(".jsonl") else path + ".jsonl"
        for variant in variants:
            run_one(path, model or None, variant, args.weights)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

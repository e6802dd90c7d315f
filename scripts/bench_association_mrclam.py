"""Data association on real robots: MRCLAM with the barcodes withheld, against the same run with them.

For each robot k of an MRCLAM folder (five iRobot Creates), in one process with BLAS on one
thread, as ``scripts/bench_mrclam.py`` does:

1. every robot's run is imported without a noise model, and a noise model is fitted on the
   *other* robots (leave-one-out: no figure comes from noise fitted on the run it scores);
2. robot k is imported with that model, once with the barcodes' landmark ids and once with
   them withheld (``fgslam import mrclam --hide-ids``: the id stays in
   ``truth_landmark_id`` for scoring only);
3. ``ekf`` and ``isam2`` run on both logs. Printed per robot and estimator: the association
   score of the hidden-id run (observations, correct, wrong — of which uses of a duplicate
   landmark —, new landmarks, duplicates, rejected; :func:`fgslam.compare.score_associations`),
   the anchored ATE against Vicon with ids and with hidden ids and their ratio; then the
   medians over the robots.

The "landmark seen" column scores the same keys against the landmark each reading saw
(:func:`seen_landmark_ids`: the barcode's, unless Vicon shows the barcode was misread).
"rejected" counts every reading left unused, of which "ambiguous" near a landmark but not
safely one (:func:`ambiguous_count`; the rest are first sightings never confirmed).
A second table gives, per robot, what an association that knew the Vicon pose and the
surveyed map would reach (:func:`with_truth_bound`): the bound on the correct share.
``--diagnose`` also prints, per robot, how many readings are misread and the
nearest-neighbour distance between the surveyed landmarks.

Usage::

    .venv/bin/python -m scripts.bench_association_mrclam ../shared/data/mrclam/MRCLAM_Dataset6
    .venv/bin/python -m scripts.bench_association_mrclam FOLDER --robots 1,2 --estimators isam2 --diagnose
"""

from __future__ import annotations

from scripts.common import one_blas_thread

one_blas_thread()

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from scripts.bench_mrclam import add_dataset_arguments, chosen_robots, leave_one_out, raw_logs  # noqa: E402
from ekf.association import DEFAULT_AMBIGUITY_MARGIN, chi2_gate  # noqa: E402
from ekf.models import range_bearing  # noqa: E402
from fgslam.cli.import_ import hide_landmark_ids  # noqa: E402
from fgslam.compare import ate_rmse_m, score_associations  # noqa: E402
from fgslam.runner import ESTIMATORS, parse_estimator_names, run_estimator, truth_trajectory  # noqa: E402
from slamio.errors import FgslamError  # noqa: E402
from slamio.geometry import wrap_angle  # noqa: E402
from slamio.log import RunLog  # noqa: E402


def run_one(log: RunLog, name: str, seen_ids: list[int | None] | None = None) -> dict:
    """ATE against the log's truth (anchored) and, when it associated, the score against
    the barcodes and, given ``seen_ids`` (:func:`seen_landmark_ids`), against the landmark
    each reading saw."""
    steps = log.steps()
    estimator = ESTIMATORS[name](log.header)
    step_keys: list[int | None] = []
    if hasattr(estimator, "step_associations"):  # keep what run_estimator reads, for the second score
        own = estimator.step_associations
        estimator.step_associations = lambda: (lambda keys: (step_keys.extend(keys), keys)[1])(own())
    run, est = run_estimator(estimator, steps, covariances=False)
    truth, has = truth_trajectory(steps)
    row = {"ate_m": ate_rmse_m(run.final, truth, has_pose=has, align=False)}
    score = run.association
    if score is not None:
        row.update(observations=score.observations, correct=score.correct, wrong=score.wrong,
                   rejected=score.rejected, new=score.landmarks_created, duplicates=len(score.duplicate_keys),
                   rate=score.rate, ambiguous=ambiguous_count(est),
                   counts=dict(getattr(est, "association_counts", None) or {}))
        if seen_ids is not None:
            keys = est.associations() if hasattr(est, "associations") else step_keys
            row["rate_seen"] = score_associations(seen_ids, keys).rate
    return row


def vicon_distances(log: RunLog) -> list[tuple[int | None, dict[int, float] | None]]:
    """Per observation (log order): its barcode's landmark and the ``d²`` of the reading to
    every surveyed landmark from the Vicon pose, with the reading's own σ (None at poses
    without truth): what an association that knew the true pose and map would see."""
    surveyed = {i: (t.x_m, t.y_m) for i, t in log.truth_landmarks().items()}
    out: list[tuple[int | None, dict[int, float] | None]] = []
    for step in log.steps():
        for o in step.observations:
            barcode = o.landmark_id if o.landmark_id is not None else o.truth_landmark_id
            if step.truth is None or barcode is None:
                out.append((barcode, None))
                continue
            pose = (step.truth.x_m, step.truth.y_m, step.truth.theta_rad)
            d2 = {}
            for i, xy in surveyed.items():
                r, b = range_bearing(pose, xy)
                d2[i] = ((o.range_m - r) / o.sigma_range_m) ** 2 + (wrap_angle(o.bearing_rad - b) / o.sigma_bearing_rad) ** 2
            out.append((barcode, d2))
    return out


def seen_landmark_ids(distances, probability: float = 0.999) -> list[int | None]:
    """Per observation, the landmark it saw: its barcode's, unless that surveyed landmark
    lies outside the reading's χ² gate (``probability``) from the Vicon pose while another
    lies inside — a misread barcode — then the nearest one (smallest d²)."""
    gate = float(chi2_gate(2, probability))
    out: list[int | None] = []
    for barcode, d2 in distances:
        if d2 is None:
            out.append(barcode)
            continue
        nearest = min(d2, key=d2.get)
        out.append(nearest if d2.get(barcode, math.inf) > gate and d2[nearest] <= gate else barcode)
    return out


def with_truth_bound(distances, margin: float = DEFAULT_AMBIGUITY_MARGIN) -> dict[str, float]:
    """What an association that knew the Vicon pose and the surveyed map would reach, as
    shares of the readings with a Vicon pose, scored against the barcodes:

    * ``nearest_is_barcode`` — pairing every reading with its most likely landmark (smallest
      ``d²``): the most any association that decides a reading from the reading alone can
      get right, since none knows the pose and the map better;
    * ``ambiguous_with_truth`` — the second most likely is within ``margin`` of the most
      likely (less than ``exp(margin / 2)`` = 100 times less likely): the estimators' rule
      (:func:`ekf.association.settle_pairing`) leaves such a reading unpaired even then;
    * ``oracle_correct`` / ``oracle_wrong`` — the others, paired with the most likely landmark,
      right or wrong: the bound for an association that follows that rule (the wrong ones are
      mostly misread barcodes, right by the landmark seen)."""
    rows = [(barcode, sorted(d2, key=d2.get), d2) for barcode, d2 in distances if d2 is not None]
    clear = [d2[order[1]] - d2[order[0]] >= margin for _, order, d2 in rows]
    right = [order[0] == barcode for barcode, order, _ in rows]
    return {"nearest_is_barcode": float(np.mean(right)), "ambiguous_with_truth": 1.0 - float(np.mean(clear)),
            "oracle_correct": float(np.mean([c and r for c, r in zip(clear, right)])),
            "oracle_wrong": float(np.mean([c and not r for c, r in zip(clear, right)]))}


def ambiguous_count(est) -> int:
    """Readings the estimator left unpaired as ambiguous (near a landmark, not safely one):
    the filter's ``rejected_observations``, the smoother's ``association_counts["rejected"]``.
    The rest of the score's "rejected" are first sightings never confirmed (smoother)."""
    counts = getattr(est, "association_counts", None)
    if counts:
        return int(counts.get("rejected", 0))
    return int(getattr(est, "rejected_observations", 0))


def landmark_spacing_m(log: RunLog) -> tuple[float, float]:
    """(smallest, median) distance from a surveyed landmark to its nearest neighbour."""
    xy = np.array([[t.x_m, t.y_m] for t in log.truth_landmarks().values()])
    d = np.linalg.norm(xy[:, None] - xy[None], axis=2) + np.eye(len(xy)) * 1e9
    nearest = d.min(axis=1)
    return float(nearest.min()), float(np.median(nearest))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_dataset_arguments(parser)
    parser.add_argument("--estimators", default="ekf,isam2", help="default ekf,isam2")
    parser.add_argument("--diagnose", action="store_true", help="also count misread barcodes per robot")
    parser.add_argument("--json", default=None, metavar="FILE", help="write every figure here")
    args = parser.parse_args(argv)
    try:
        names = parse_estimator_names(args.estimators, need_isam2=False)
    except FgslamError as exc:
        parser.error(str(exc))
    raw = raw_logs(args.folder)
    robots = chosen_robots(args.robots, raw)
    results: dict[int, dict] = {}
    oracles: list[str] = []
    print("| robot | estimator | observations | correct (barcodes) | correct (landmark seen) | wrong | new (dup.) | rejected "
          "(ambiguous) | ATE ids m | ATE hidden m | ratio |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for k in robots:
        header, records, _ = leave_one_out(args.folder, k, raw)
        with_ids = RunLog(f"robot{k}", header, tuple(records))
        hidden_header, hidden_records = hide_landmark_ids(header, records)
        hidden = RunLog(f"robot{k} hidden", hidden_header, tuple(hidden_records))
        distances = vicon_distances(hidden)
        seen = seen_landmark_ids(distances)
        barcodes = [barcode for barcode, _ in distances]
        bound = with_truth_bound(distances)
        results[k] = {"misread": sum(a != b for a, b in zip(seen, barcodes)), "readings": len(seen), **bound}
        oracles.append(f"| {k} | {100 * bound['nearest_is_barcode']:.1f} % | {100 * bound['oracle_correct']:.1f} % | "
                       f"{100 * bound['ambiguous_with_truth']:.1f} % | {100 * bound['oracle_wrong']:.1f} % | "
                       f"{results[k]['misread']} |")
        if args.diagnose:
            closest, median = landmark_spacing_m(with_ids)
            print(f"robot {k}: {results[k]['misread']} of {len(seen)} readings misread (barcode's landmark outside the "
                  f"99.9 % gate from the Vicon pose, another inside); from the Vicon pose the nearest surveyed landmark "
                  f"is the barcode's for {100 * bound['nearest_is_barcode']:.1f} %, a second within the ambiguity "
                  f"margin for {100 * bound['ambiguous_with_truth']:.1f} %; nearest-neighbour distance between "
                  f"surveyed landmarks {closest:.2f} m min, {median:.2f} m median", file=sys.stderr, flush=True)
        for name in names:
            ids_row, hid_row = run_one(with_ids, name), run_one(hidden, name, seen)
            hid_row["ate_ids_m"] = ids_row["ate_m"]
            results[k][name] = hid_row
            print(f"| {k} | {name} | {hid_row['observations']} | {hid_row['correct']} ({100 * hid_row['rate']:.1f} %) | "
                  f"{100 * hid_row['rate_seen']:.1f} % | {hid_row['wrong']} | {hid_row['new']} ({hid_row['duplicates']}) | "
                  f"{hid_row['rejected']} ({hid_row['ambiguous']}) | {ids_row['ate_m']:.3f} | {hid_row['ate_m']:.3f} | "
                  f"{hid_row['ate_m'] / ids_row['ate_m']:.2f} |", flush=True)
            print(f"robot {k} {name}: {hid_row['counts']}", file=sys.stderr, flush=True)
    for name in names:
        rows = [results[k][name] for k in robots]
        med = {c: float(np.median([r[c] for r in rows]))
               for c in ("rate", "rate_seen", "wrong", "new", "rejected", "ambiguous", "ate_ids_m", "ate_m")}
        ratio = float(np.median([r["ate_m"] / r["ate_ids_m"] for r in rows]))
        print(f"| median | {name} | | {100 * med['rate']:.1f} % | {100 * med['rate_seen']:.1f} % | {med['wrong']:.0f} | "
              f"{med['new']:.0f} | {med['rejected']:.0f} ({med['ambiguous']:.0f}) | {med['ate_ids_m']:.3f} | {med['ate_m']:.3f} | {ratio:.2f} |")
    print("\nWith the Vicon pose and the surveyed map (the bound; shares of the readings with a Vicon pose):\n")
    print("| robot | nearest is the barcode's | paired, right | ambiguous (left unpaired) | paired, wrong | misread |")
    print("|---|---|---|---|---|---|")
    print("\n".join(oracles))
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""What a relinearisation check costs, taken apart by GTSAM's own prediction of the re-elimination.

Question (issue 43, part 4): why do 300 variables relinearised in one check re-eliminate
1 500–2 300 variables on Plaza1 and Victoria Park? The default ``isam2`` (``fgslam run``'s,
with ``relinearize_choice`` from ``--history``: by default ``"ratio"``, the rule these long
checks came from) runs a log up to step ``STEP`` (the step of a long check, before it); then, on that
iSAM2, ``ISAM2.predictUpdateInfo`` (a check forced, every variable but the named ones held
back) counts the variables an update relinearising only these would re-eliminate: the 300
the ratio rule chooses (the first rule of :class:`fgslam.smoother.relinearisation.CapChoice`),
its poses alone and its landmarks alone; one pose at a few ages (entries since it entered);
each landmark (a sample of 40 on a large map), with its factor count; 300 consecutive poses
at a few ages; and the block the default (``relinearize_choice="block"``) chooses. The answer
is in docs/performance.md, "Relinearising a block of neighbours".

Usage::

    .venv/bin/python -m scripts.experiments.long_steps_paths plaza1 11755
    .venv/bin/python -m scripts.experiments.long_steps_paths victoria-park 4535
"""

from __future__ import annotations

from scripts import bench_long_steps  # first: it pins BLAS to one thread before numpy loads

import argparse  # noqa: E402

import gtsam  # noqa: E402
import numpy as np  # noqa: E402

from fgslam.registry import expected_outlier_kernel  # noqa: E402
from fgslam.smoother import Isam2Smoother  # noqa: E402
from fgslam.smoother.relinearisation import block_start, key_list  # noqa: E402
from slamio.log import group_steps  # noqa: E402

_KIND_SHIFT = np.uint64(56)  # a key's character is in its top 8 bits (gtsam.Symbol)


def reeliminated(isam, keys: np.ndarray, only) -> int:
    """Variables an update of ``isam`` that relinearises only ``only`` (of those past the
    threshold) would re-eliminate, by GTSAM's prediction."""
    params = gtsam.ISAM2UpdateParams()
    params.force_relinearize = True
    params.noRelinKeys = key_list(np.setdiff1d(keys, np.asarray(only, dtype=np.uint64)))
    affected, _ = isam.predictUpdateInfo(gtsam.NonlinearFactorGraph(), gtsam.Values(), params)
    return affected.size()


def report(name: str, stop: int, width: int, history: str) -> None:
    header, records = bench_long_steps.load(name)
    smoother = Isam2Smoother(header, robust=expected_outlier_kernel(header), relinearize_max_variables=width,
                             relinearize_choice=history)
    for step in group_steps(header, records)[:stop]:
        smoother.step(step)
    isam, cap = smoother._isam, smoother._cap
    ratio, keys = cap.ratios(isam), cap._array  # in the order the keys entered
    past = np.flatnonzero(ratio >= 1.0)
    chosen = keys[past[np.lexsort((keys[past], -ratio[past]))][:width]]
    is_pose = (chosen >> _KIND_SHIFT) == ord("x")
    entry = {int(k): i for i, k in enumerate(keys)}
    ages = np.array([len(keys) - 1 - entry[int(k)] for k in chosen])
    print(f"## {name} before step {stop} ({history} choices so far): {len(keys)} variables, {len(past)} past the threshold, "
          f"ratios up to {ratio[past].max():.1f}")
    print(f"the ratio rule's {len(chosen)}: {int(is_pose.sum())} poses, ages {int(ages.min())}-{int(ages.max())} "
          f"(median {float(np.median(ages)):.0f}); re-eliminated: all {reeliminated(isam, keys, chosen)}, "
          f"poses alone {reeliminated(isam, keys, chosen[is_pose])}, "
          f"landmarks alone {reeliminated(isam, keys, chosen[~is_pose])}")
    poses = np.sort(keys[(keys >> _KIND_SHIFT) == ord("x")])
    for age in (1000, 2000, 4000, 8000):
        if age < len(poses):
            print(f"one pose {age} poses old: {reeliminated(isam, keys, [poses[-1 - age]])}")
    landmarks = keys[(keys >> _KIND_SHIFT) != ord("x")]
    sample = landmarks if len(landmarks) <= 40 else np.random.default_rng(0).choice(landmarks, 40, replace=False)
    index = isam.getVariableIndex()
    per_landmark = sorted((len(index.at(int(k))), reeliminated(isam, keys, [k])) for k in sample)
    print(f"one landmark (factors, re-eliminated): {per_landmark}")
    for age in (0, 300, 3000, 8000):
        if age + width < len(poses):
            block = poses[len(poses) - 1 - age - width:len(poses) - 1 - age]
            print(f"{width} consecutive poses from {age} old: {reeliminated(isam, keys, block)}")
    weights = np.where(ratio >= 1.0, np.minimum(ratio, 2.0**40), 0.0)
    start = block_start(weights, width)
    block = keys[start:start + width][ratio[start:start + width] >= 1.0]
    print(f"the block choice: {len(block)} past the threshold from {len(keys) - 1 - start} old: "
          f"{reeliminated(isam, keys, block)}\n", flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("log", help="as scripts.bench_long_steps")
    ap.add_argument("step", type=int, help="run the steps before this one, then take the check apart")
    ap.add_argument("--width", type=int, default=300, help="the cap (relinearize_max_variables)")
    ap.add_argument("--history", choices=("ratio", "block"), default="ratio",
                    help="the relinearize_choice of the run up to the check")
    args = ap.parse_args(argv)
    report(args.log, args.step, args.width, args.history)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Does a capped relinearisation check that always takes the variables far from their
linearisation point avoid MRCLAM robot 5's failed update, and what does it cost?

Question (issue 43, part 4): with ``relinearize_choice="block"`` a check relinearises only
the variables past the threshold within one block of ``relinearize_max_variables``
consecutive variables, so a variable outside every heaviest block can wait for many checks
(MRCLAM Dataset 6 robot 5, round noise: ``l7`` held back with a pending step of 0.9–1.4 m
before the failed update at pose 2743). This experiment runs ``scripts.bench_long_steps``
with the default ``isam2`` whose cap (:class:`fgslam.smoother.relinearisation.CapChoice`)
also relinearises the *far* variables — pending step at least ``--far-ratio`` thresholds,
the ``--far-max`` furthest of them — on top of the block (total ≤ cap + far-max), or, with
``--far-first``, takes them first and fills the rest of the cap with a block of the others
(total ≤ cap).

``--watch K`` (landmark indices, e.g. ``7``) prints, at each capped check, each watched
landmark's ratio, rank, pending step and whether it was held back; and at each failed update
(before the rebuild) the pending step of the watched landmarks and of the furthest variables.

Usage::

    .venv/bin/python -m scripts.experiments.long_steps_far mrclam:5 --far-ratio 50 --far-max 100 --watch 7
    .venv/bin/python -m scripts.experiments.long_steps_far mrclam:5 --uncapped --watch 7
    .venv/bin/python -m scripts.experiments.long_steps_far victoria-park plaza1 --far-ratio 50 --far-max 100
"""

from __future__ import annotations

from scripts import bench_long_steps  # first: it pins BLAS to one thread before numpy loads

import argparse  # noqa: E402

import gtsam  # noqa: E402
import numpy as np  # noqa: E402

from fgslam.smoother import relinearisation  # noqa: E402
from fgslam.smoother.relinearisation import CapChoice, block_start, key_list  # noqa: E402


def block_and_far(ratio: np.ndarray, past: np.ndarray, width: int, far_ratio: float, far_max: int,
                  far_first: bool) -> np.ndarray:
    """Indices of the variables to relinearise (sorted): the ``far_max`` furthest of those
    with ``ratio >= far_ratio`` and those of ``past`` within the heaviest block of the
    others (``width`` wide, or ``width`` less the far ones with ``far_first``)."""
    far = past[ratio[past] >= far_ratio]
    if len(far) > far_max:
        far = far[np.lexsort((far, -ratio[far]))[:far_max]]
    width = width - len(far) if far_first else width
    weights = np.zeros(len(ratio))
    weights[past] = np.minimum(ratio[past], relinearisation._RATIO_CEILING)
    weights[far] = 0.0
    start = block_start(weights, width)
    block = past[(past >= start) & (past < start + width)]
    return np.union1d(block, far)


def far_held_back(far_ratio: float, far_max: int, far_first: bool, watch: list[int]):
    """CapChoice.held_back with the far variables always taken (and the watched keys logged)."""
    checks = [0]

    def held_back(self: CapChoice, isam) -> gtsam.KeyList:
        ratio = self.ratios(isam)
        if ratio is None:
            return gtsam.KeyList()
        checks[0] += 1
        past = np.flatnonzero(ratio >= 1.0)
        if len(past) <= self._max_variables:
            held = np.empty(0, dtype=past.dtype)
        else:
            chosen = block_and_far(ratio, past, self._max_variables, far_ratio, far_max, far_first)
            held = np.setdiff1d(past, chosen, assume_unique=True)
        _log_watched(checks[0], isam, self._keys, ratio, len(past), set(self._array[held].tolist()), watch)
        return key_list(self._array[held]) if len(held) else gtsam.KeyList()

    return held_back


def _log_watched(check: int, isam, keys: list[int], ratio: np.ndarray, past: int, held: set, watch: list[int]) -> None:
    for key in watch:
        if key not in keys:
            continue
        i = keys.index(key)
        step = np.linalg.norm(isam.getDelta().at(key))
        print(f"  check {check}: {len(keys)} variables, {past} past the threshold (largest ratio "
              f"{ratio.max():.0f}); {gtsam.Symbol(key).string()} ratio {ratio[i]:.1f} (rank {int((ratio > ratio[i]).sum())}), "
              f"pending step {step:.3f} m, {'held back' if key in held else 'relinearised'}")


def logged_rebuild(watch: list[int]):
    """fgslam.smoother.updates.rebuild, first printing the broken ISAM2's pending steps."""
    plain = bench_long_steps.PLAIN["rebuild"]

    def rebuild(exc, isam, *args, **kwargs):
        delta = isam.getDelta()
        steps = {key: float(np.linalg.norm(delta.at(key)[:2])) for key in isam.getLinearizationPoint().keys()}
        furthest = sorted(steps, key=lambda key: -steps[key])[:3]
        watched = ", ".join(f"{gtsam.Symbol(k).string()} {steps[k]:.3f} m" for k in watch if k in steps)
        print(f"  failed update ({' '.join(str(exc).split()[:9])}): pending step {watched}; furthest "
              + ", ".join(f"{gtsam.Symbol(k).string()} {steps[k]:.2f} m" for k in furthest)
              + f"; {sum(s > 0.5 for s in steps.values())} of {len(steps)} variables beyond 0.5 m")
        return plain(exc, isam, *args, **kwargs)

    return rebuild


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="+", help="as scripts.bench_long_steps")
    ap.add_argument("--far-ratio", type=float, default=float("inf"), help="pending step / threshold from which a variable is far")
    ap.add_argument("--far-max", type=int, default=0, help="at most this many far variables a check")
    ap.add_argument("--far-first", action="store_true", help="the far ones count against the cap (the block is narrower)")
    ap.add_argument("--uncapped", action="store_true", help="every variable past the threshold (no cap)")
    ap.add_argument("--watch", default="", help="landmark indices to log, e.g. 7 or 6,7,8")
    ap.add_argument("--top", type=int, default=3)
    args = ap.parse_args(argv)
    watch = [gtsam.symbol("l", int(i)) for i in args.watch.split(",") if i]
    far_ratio, far_max = (0.0, 10**9) if args.uncapped else (args.far_ratio, args.far_max)
    bench_long_steps.PLAIN["held_back"] = far_held_back(far_ratio, far_max, args.far_first, watch)
    if watch:
        bench_long_steps.PLAIN["rebuild"] = logged_rebuild(watch)
    print(f"# far variables: ratio >= {far_ratio}, at most {far_max}, first: {args.far_first}")
    for name in args.logs:
        bench_long_steps.report(name, args.top, False)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

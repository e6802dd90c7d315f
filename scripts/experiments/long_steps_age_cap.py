"""Does a relinearisation check that leaves old variables alone bound the long steps?

Question (issue 43, part 4): a check's cost is the re-elimination of every clique from each
relinearised variable up to the root, so one old variable makes the whole check deep. This
experiment runs ``scripts.bench_long_steps`` with the default ``isam2`` whose cap
(:class:`fgslam.smoother.relinearisation.CapChoice`) also holds back every variable past the
threshold that entered iSAM2 more than ``--max-age`` variables ago (its age: the variables
entered after it), so only the young part of the tree is relinearised online; the old part
waits for ``finish()``'s Gauss–Newton steps. ``--landmarks-exempt`` keeps the age limit for
poses only (a landmark left at a stale linearisation point was what cost the fourth round's
"poses first" cap its accuracy). The step times, online ATE and final χ²/2 against the batch
optimum are bench_long_steps' own.

Ages count from the order the variables entered the ``ISAM2`` the cap keeps keys for; after a
rebuild or a window's slide the keys are read back in key order (landmarks first), so ages are
approximate there (MRCLAM robot 5 rebuilds once).

Usage::

    .venv/bin/python -m scripts.experiments.long_steps_age_cap victoria-park plaza1 --max-age 500
    .venv/bin/python -m scripts.experiments.long_steps_age_cap grid:2000 --max-age 500 --landmarks-exempt
"""

from __future__ import annotations

from scripts import bench_long_steps  # first: it pins BLAS to one thread before numpy loads

import argparse  # noqa: E402

import gtsam  # noqa: E402
import numpy as np  # noqa: E402

from fgslam.smoother.relinearisation import CapChoice, key_list  # noqa: E402

_LANDMARK = np.uint64(ord("l"))
_KIND_SHIFT = np.uint64(56)  # a key's character is in its top 8 bits (gtsam.Symbol)


def aged_held_back(max_age: int, landmarks_exempt: bool):
    """CapChoice.held_back that also holds back the variables older than ``max_age``."""

    def held_back(self: CapChoice, isam) -> gtsam.KeyList:
        ratio = self.ratios(isam)
        if ratio is None:
            return gtsam.KeyList()
        age = len(self._keys) - 1 - np.arange(len(self._keys))
        old = age > max_age
        if landmarks_exempt:
            old &= (self._array >> _KIND_SHIFT) != _LANDMARK
        past = np.flatnonzero(ratio >= 1.0)
        young = past[~old[past]]
        keys = self._array[young]
        chosen = young[np.lexsort((keys, -ratio[young]))][:self._max_variables]
        held = np.setdiff1d(past, chosen, assume_unique=True)
        return key_list(self._array[held]) if len(held) else gtsam.KeyList()

    return held_back


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="+", help="as scripts.bench_long_steps")
    ap.add_argument("--max-age", type=int, required=True, help="variables entered after it beyond which one waits")
    ap.add_argument("--landmarks-exempt", action="store_true", help="the age limit for poses only")
    ap.add_argument("--top", type=int, default=5)
    args = ap.parse_args(argv)
    bench_long_steps.PLAIN["held_back"] = aged_held_back(args.max_age, args.landmarks_exempt)
    print(f"# age cap: max age {args.max_age} variables, landmarks exempt: {args.landmarks_exempt}")
    for name in args.logs:
        bench_long_steps.report(name, args.top, False)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

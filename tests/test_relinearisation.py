"""When the default ``isam2`` relinearises, and what checking less often costs.

The default checks relinearisation on every 20th iSAM2 update (``relinearize_skip``) and
relinearises at most 300 variables in a check (``relinearize_max_variables``), those past the
threshold in the block of 300 consecutive variables (in the order they entered) whose
ratios sum highest (``relinearize_choice``; docs/performance.md has the measurements behind
all three). Checked here against independent
references: GTSAM's own per-update report of the variables it relinearised, its
linearisation point before and after each update, an iSAM2 that updates and checks
relinearisation at every step, and the batch optimum.
"""

from __future__ import annotations

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import H, L, T, X

from fgslam.smoother import Isam2Smoother, batch_solve
from fgslam.smoother.relinearisation import CapChoice, block_start, component_thresholds, key_list, ratios
from slamio.errors import FgslamError
from slamio.log import group_steps
from slamio.sim import simulate


class _RecordingIsam2:
    """Forwards to an ``ISAM2`` and keeps how many variables each update relinearised."""

    def __init__(self, isam):
        self._isam = isam
        self.relinearised: list[int] = []

    def update(self, *args):
        result = self._isam.update(*args)
        self.relinearised.append(result.getVariablesRelinearized())
        return result

    def __getattr__(self, name):
        return getattr(self._isam, name)


def _online(smoother, steps) -> np.ndarray:
    out = np.empty((len(steps), 3))
    for i, step in enumerate(steps):
        smoother.step(step)
        out[i] = smoother.current_pose()
    return out


def _ate_m(poses: np.ndarray, steps) -> float:
    truth = np.array([[s.truth.x_m, s.truth.y_m] for s in steps])
    return float(np.sqrt(np.mean(np.sum((poses[:, :2] - truth) ** 2, axis=1))))


def test_relinearisation_is_checked_on_every_20th_update_only():
    header, records = simulate("arena-octagon", 2)
    steps = group_steps(header, records)
    smoother = Isam2Smoother(header)
    assert smoother.settings.relinearize_skip == 20
    recording = smoother._isam = _RecordingIsam2(smoother._isam)
    _online(smoother, steps)
    assert smoother.update_failures == 0  # the recorder saw every update of one iSAM2
    checked = [i for i, n in enumerate(recording.relinearised) if n > 0]
    assert len(recording.relinearised) > 40 and checked  # several checks, some relinearised
    assert all(i % 20 == 19 for i in checked)  # the 20th, 40th, … update


def test_default_matches_every_step_isam2_online_and_batch_at_the_end():
    """The issue's accuracy gates on one simulated arena run: the default's online ATE
    within 3 % of an iSAM2 that updates and checks relinearisation at every step (without
    the online correction), and its final χ² within 0.1 % of the batch optimum."""
    header, records = simulate("arena-octagon", 3)
    steps = group_steps(header, records)
    reference = Isam2Smoother(header, update_every=1, relinearize_skip=1, online_correction=False,
                              wildfire_threshold=0.001)
    default = Isam2Smoother(header)
    reference_ate = _ate_m(_online(reference, steps), steps)
    default_ate = _ate_m(_online(default, steps), steps)
    assert default.updates < len(steps) / 5  # it did hold steps
    assert default_ate < 1.03 * reference_ate
    default.finish()
    batch = batch_solve(default)
    assert default.error() < 1.001 * batch.final_error


def test_while_associating_relinearisation_is_checked_on_every_10th_update():
    """Observations without an id: the smoother's pairing decisions read the map, so the
    check runs on every 10th update as well (the 10th, 30th, … are the smoother's own)."""
    header, records = simulate("arena-octagon", 2, hide_ids=True)
    steps = group_steps(header, records)
    smoother = Isam2Smoother(header)
    recording = smoother._isam = _RecordingIsam2(smoother._isam)
    _online(smoother, steps)
    assert smoother.update_failures == 0
    checked = [i + 1 for i, n in enumerate(recording.relinearised) if n > 0]  # n-th update, from 1
    assert all(n % 10 == 0 for n in checked)
    assert any(n % 20 == 10 for n in checked)  # checks GTSAM's every-20th schedule would not run


# ---------------------------------------------------------------- relinearize_max_variables


class _LinearisationPoints:
    """Forwards to an ``ISAM2`` and counts, per update, the variables it already held whose
    linearisation point the update moved (read from GTSAM before and after, not from the
    smoother's own bookkeeping)."""

    def __init__(self, isam):
        self._isam = isam
        self.moved: list[int] = []

    def update(self, *args):
        before = gtsam.Values(self._isam.getLinearizationPoint())  # a copy: GTSAM returns its own
        result = self._isam.update(*args)
        after = self._isam.getLinearizationPoint()
        self.moved.append(sum(_moved(before, after, key) for key in before.keys()))
        return result

    def __getattr__(self, name):
        return getattr(self._isam, name)


def _moved(before, after, key) -> bool:
    symbol = chr(gtsam.Symbol(key).chr())
    if symbol == "x":
        return not after.atPose2(key).equals(before.atPose2(key), 0.0)
    if symbol == "l":
        return not np.array_equal(after.atPoint2(key), before.atPoint2(key))
    raise AssertionError(f"unexpected variable {symbol}")


def test_a_capped_check_relinearises_at_most_that_many_variables():
    header, records = simulate("arena-octagon", 2)
    steps = group_steps(header, records)
    uncapped = Isam2Smoother(header, relinearize_skip=1, relinearize_max_variables=None)
    capped = Isam2Smoother(header, relinearize_skip=1, relinearize_max_variables=5)
    runs = {}
    for name, smoother in (("uncapped", uncapped), ("capped", capped)):
        recording = smoother._isam = _LinearisationPoints(smoother._isam)
        _online(smoother, steps)
        assert smoother.update_failures == 0
        runs[name] = recording.moved
    assert max(runs["uncapped"]) > 5  # without the cap some update relinearised more
    assert max(runs["capped"]) <= 5
    assert sum(runs["capped"]) > 0  # … and with it, the checks still relinearise


def test_capped_relinearisation_matches_every_step_isam2_online_and_batch_at_the_end():
    """The same accuracy gates as the default's (above) with the cap on every update's check."""
    header, records = simulate("arena-octagon", 3)
    steps = group_steps(header, records)
    reference = Isam2Smoother(header, update_every=1, relinearize_skip=1, online_correction=False,
                              wildfire_threshold=0.001)
    capped = Isam2Smoother(header, relinearize_skip=10, relinearize_max_variables=20)
    reference_ate = _ate_m(_online(reference, steps), steps)
    capped_ate = _ate_m(_online(capped, steps), steps)
    assert capped_ate < 1.03 * reference_ate
    capped.finish()
    batch = batch_solve(capped)
    assert capped.error() < 1.001 * batch.final_error


def test_while_associating_the_cap_is_not_applied():
    """Observations without an id keep the every-10th uncapped check: the same online poses
    with and without the cap."""
    header, records = simulate("arena-octagon", 2, hide_ids=True)
    steps = group_steps(header, records)
    plain = _online(Isam2Smoother(header, relinearize_max_variables=None), steps)
    capped = _online(Isam2Smoother(header, relinearize_max_variables=1), steps)
    np.testing.assert_array_equal(plain, capped)


def test_ratios_per_component_against_the_threshold():
    """|step| / threshold per variable, the largest component: one threshold for all, and
    the (metres, radians) pair the smoother gives GTSAM as its per-type map (θ in radians)."""
    keys = [L(3), X(0), H(3)]
    delta = gtsam.VectorValues()
    delta.insert(X(0), np.array([0.002, -0.004, 0.03]))
    delta.insert(L(3), np.array([-0.05, 0.01]))
    delta.insert(H(3), np.array([0.2]))
    thresholds, starts = component_thresholds(keys, (0.1, 0.01))
    np.testing.assert_array_equal(thresholds, [0.1, 0.1, 0.1, 0.1, 0.01, 0.1])
    np.testing.assert_array_equal(starts, [0, 2, 5])
    np.testing.assert_allclose(ratios(delta, keys, 0.01), [5.0, 3.0, 20.0])
    np.testing.assert_allclose(ratios(delta, keys, (0.1, 0.01)), [0.5, 3.0, 2.0])
    assert np.isinf(ratios(delta, keys, (0.0, 0.01))).all()  # GTSAM relinearises every variable at 0


def test_a_negative_cap_is_refused():
    header, _ = simulate("arena-octagon", 2)
    with pytest.raises(FgslamError, match="relinearize_max_variables"):
        Isam2Smoother(header, relinearize_max_variables=-1)


def _capped_at_zero_recording(header, **settings):
    """A smoother checking every third update with every variable past a zero threshold and a
    cap of 0, and the linearisation points of each ISAM2 it makes (the first, each rebuilt or
    slid one), in order."""
    smoother = Isam2Smoother(header, update_every=1, relinearize_skip=3, relinearize_threshold=0.0,
                             relinearize_max_variables=0, **settings)
    records = []

    def recorded(isam):
        records.append(_LinearisationPoints(isam))
        return records[-1]

    smoother._isam_wrapper = recorded
    smoother._isam = smoother._new_isam(smoother._isam)
    return smoother, records


def test_after_a_rebuild_the_cap_still_falls_on_gtsams_checks():
    """A failed update rebuilds iSAM2 with one update of its own; GTSAM counts it, so the
    smoother must too, or its cap is computed on updates GTSAM does not check and GTSAM's
    checks run uncapped. With every variable past a zero threshold and a cap of 0, no check
    may move a linearisation point (read from GTSAM before and after each update), before
    or after the rebuild."""
    from loop_logs import junk, make_loop_log, with_extra

    header, steps, _, _ = make_loop_log(n_steps=60)
    smoother, records = _capped_at_zero_recording(header)
    for step in steps:
        smoother.step(with_extra(step, junk(step, 99)) if step.index == 20 else step)
    assert smoother.update_failures == 1 and len(records) == 2  # the first ISAM2 and the rebuilt one
    assert len(records[1].moved) >= 3 * 3  # several checks after the rebuild
    assert sum(records[0].moved) == 0 and sum(records[1].moved) == 0
    # the independent half: without the cap GTSAM's checks do move them, on both objects
    plain = Isam2Smoother(header, update_every=1, relinearize_skip=3, relinearize_threshold=0.0,
                          relinearize_max_variables=None)
    recording = plain._isam = _LinearisationPoints(plain._isam)
    for step in steps[:20]:
        plain.step(step)
    assert sum(recording.moved) > 0


def test_after_a_window_slide_the_cap_still_falls_on_gtsams_checks():
    """The fresh iSAM2 a slide starts (fgslam/smoother/window.py) has had one update, the
    window's: counted as GTSAM counts it, no capped check moves a linearisation point."""
    from loop_logs import make_loop_log

    header, steps, _, _ = make_loop_log(n_steps=80)
    smoother, records = _capped_at_zero_recording(header, window_poses=10)
    for step in steps:
        smoother.step(step)
    assert smoother.window_slides >= 2 and smoother.update_failures == 0
    assert all(len(r.moved) >= 4 for r in records[1:-1])  # checks ran on each fresh iSAM2
    assert sum(sum(r.moved) for r in records) == 0


def test_key_list_holds_exactly_the_keys_given():
    """noRelinKeys built per symbol character (the poses in one createKeyList call): the same
    keys as a push_back per key, whatever their kinds and however large their indices."""
    rng = np.random.default_rng(0)
    keys = ([X(int(i)) for i in rng.choice(10**6, 400, replace=False)] + [L(i) for i in range(30)]
            + [T(5), H(2), X(2**53 - 1), X(2**53 + 5), X(2**55 + 3)])
    rng.shuffle(keys)
    out, got = key_list(np.array(keys, dtype=np.uint64)), []
    while not out.empty():
        got.append(out.front())
        out.pop_front()
    assert sorted(got) == sorted(keys)
    assert key_list(np.array([], dtype=np.uint64)).empty()


# ---------------------------------------------------------------- the cap's choice, kept keys


def _reference_held_back(isam, threshold, max_variables) -> list[int]:
    """The cap's choice as it was first written: every key read back from iSAM2's
    linearisation point (sorted by key), ranked by ratio with a stable sort, the first
    ``max_variables`` dropped."""
    keys = isam.getLinearizationPoint().keys()
    ratio = ratios(isam.getDelta(), keys, threshold)
    past = np.flatnonzero(ratio >= 1.0)
    if len(past) <= max_variables:
        return []
    chosen = past[np.argsort(-ratio[past], kind="stable")][max_variables:]
    return [int(k) for k in np.asarray(keys, dtype=np.uint64)[chosen]]


def _listed(keys: gtsam.KeyList) -> list[int]:
    out = gtsam.KeyList(keys)
    got = []
    while not out.empty():
        got.append(out.front())
        out.pop_front()
    return got


class _ComparedCap:
    """The smoother's CapChoice, each choice compared with the reference's on the same iSAM2."""

    def __init__(self, cap: CapChoice, threshold, max_variables):
        self._cap, self._threshold, self._max = cap, threshold, max_variables
        self.choices: list[list[int]] = []

    def entered(self, isam, values):
        self._cap.entered(isam, values)

    def held_back(self, isam):
        out = self._cap.held_back(isam)
        expected = _reference_held_back(isam, self._threshold, self._max)
        got = _listed(out)
        assert sorted(got) == sorted(expected)  # GTSAM reads noRelinKeys as a set …
        poses = [k for k in expected if chr(gtsam.Symbol(k).chr()) == "x"]
        assert got == poses + [k for k in expected if k not in set(poses)]  # … and key_list puts the poses first
        self.choices.append(got)
        return out


def _compared(smoother) -> _ComparedCap:
    settings = smoother.settings
    smoother._cap = _ComparedCap(smoother._cap, settings.relinearize_threshold, settings.relinearize_max_variables)
    return smoother._cap


@pytest.mark.parametrize("settings", [
    dict(relinearize_skip=2, relinearize_max_variables=5, relinearize_choice="ratio"),  # a real threshold: ranked by ratio
    dict(update_every=1, relinearize_skip=3, relinearize_threshold=0.0, relinearize_max_variables=4,
         relinearize_choice="ratio"),  # all tied
])
def test_the_kept_keys_choose_what_a_full_read_chooses(settings):
    """Through a whole run (poses, landmarks and tags entering between checks), every check's
    held-back keys are the ones the first implementation chose from a full read of iSAM2's
    keys: the same keys, in the same order by ratio with ties broken by key."""
    header, records = simulate("arena-octagon", 2)
    steps = group_steps(header, records)
    smoother = Isam2Smoother(header, tags=True, **settings)
    compared = _compared(smoother)
    _online(smoother, steps)
    assert smoother.update_failures == 0
    held = [c for c in compared.choices if c]
    assert len(held) >= 5  # several checks held something back
    kinds = {chr(gtsam.Symbol(k).chr()) for c in held for k in c}
    assert kinds >= {"x", "l"} or kinds >= {"x", "t"}


def test_the_kept_keys_are_read_again_after_a_rebuild_and_a_slide():
    """A rebuilt iSAM2 and a slid window's fresh one are other objects: the keys are read back
    from them, and every choice still matches the full read."""
    from loop_logs import junk, make_loop_log, with_extra

    header, steps, _, _ = make_loop_log(n_steps=80)
    for extra in (dict(), dict(window_poses=10)):
        smoother = Isam2Smoother(header, update_every=1, relinearize_skip=3, relinearize_threshold=0.0,
                                 relinearize_max_variables=2, relinearize_choice="ratio", **extra)
        compared = _compared(smoother)
        for step in steps:
            smoother.step(with_extra(step, junk(step, 99)) if step.index == 20 and not extra else step)
        assert smoother.update_failures == (0 if extra else 1)
        assert smoother.window_slides >= (2 if extra else 0)
        assert sum(1 for c in compared.choices if c) >= 10


def test_the_kept_keys_are_read_again_when_iSAM2_holds_others():
    """Keys entered into iSAM2 without :meth:`CapChoice.entered` (another caller's update) are
    noticed by the count of variables, and the choice is the full read's."""
    isam = gtsam.ISAM2()
    noise = gtsam.noiseModel.Isotropic.Sigma(3, 0.1)
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    graph.add(gtsam.PriorFactorPose2(X(0), gtsam.Pose2(), noise))
    values.insert(X(0), gtsam.Pose2(0.3, 0.0, 0.0))
    isam.update(graph, values)
    cap = CapChoice(0.0, 1, "ratio")
    assert _listed(cap.held_back(isam)) == []  # one variable, the cap is 1
    for i in range(1, 4):
        graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        graph.add(gtsam.BetweenFactorPose2(X(i - 1), X(i), gtsam.Pose2(1.0, 0.0, 0.0), noise))
        values.insert(X(i), gtsam.Pose2(i + 0.2, 0.1, 0.0))
        isam.update(graph, values)  # not told to the cap
    assert _listed(cap.held_back(isam)) == _reference_held_back(isam, 0.0, 1) == [X(1), X(2), X(3)]


# ---------------------------------------------------------------- the block choice


class _EntryOrder:
    """Forwards to an ``ISAM2`` and keeps the keys of every successful update's new values, in
    the order they entered (read from the calls, not from the smoother's cap)."""

    def __init__(self, isam):
        self._isam = isam
        self.keys: list[int] = []
        self.reeliminated_in_checks: list[int] = []

    def update(self, *args):
        result = self._isam.update(*args)
        if len(args) > 1:
            self.keys.extend(args[1].keys())
        if len(args) == 3:  # a capped check (the smoother passes ISAM2UpdateParams only then)
            self.reeliminated_in_checks.append(result.getVariablesReeliminated())
        return result

    def __getattr__(self, name):
        return getattr(self._isam, name)


def _reference_block_held_back(isam, entry_order: list[int], threshold, width: int) -> list[int]:
    """The block choice by brute force: every window of ``width`` consecutive keys in entry
    order summed in Python, the first with the largest sum kept; every other key past the
    threshold held back."""
    ratio = [min(float(r), 2.0**40) for r in ratios(isam.getDelta(), entry_order, threshold)]
    past = [r >= 1.0 for r in ratio]
    if sum(past) <= width:
        return []
    weights = [r if p else 0.0 for r, p in zip(ratio, past)]
    sums = [sum(weights[i:i + width]) for i in range(len(weights) - width + 1)]
    start = sums.index(max(sums))
    return [k for i, k in enumerate(entry_order) if past[i] and not start <= i < start + width]


@pytest.mark.parametrize("settings", [
    dict(relinearize_skip=2, relinearize_max_variables=5),
    dict(update_every=1, relinearize_skip=3, relinearize_threshold=0.0, relinearize_max_variables=4),  # all tied
])
def test_the_block_choice_holds_back_all_but_the_heaviest_block_in_entry_order(settings):
    """Through a whole run (poses, landmarks and tags entering between checks), every check
    holds back exactly what the brute-force block choice holds back, over the keys in the
    order the updates entered them."""
    header, records = simulate("arena-octagon", 2)
    steps = group_steps(header, records)
    smoother = Isam2Smoother(header, tags=True, **settings)
    assert smoother.settings.relinearize_choice == "block"  # the default
    order = smoother._isam = _EntryOrder(smoother._isam)
    cap, checked = smoother._cap, []

    class Compared:
        def entered(self, isam, values):
            cap.entered(isam, values)

        def held_back(self, isam):
            out = cap.held_back(isam)
            expected = _reference_block_held_back(isam, order.keys, settings.get("relinearize_threshold", 0.01),
                                                  settings["relinearize_max_variables"])
            assert sorted(_listed(out)) == sorted(expected)
            checked.append(len(expected))
            return out

    smoother._cap = Compared()
    _online(smoother, steps)
    assert smoother.update_failures == 0
    assert sum(1 for n in checked if n) >= 5  # several checks held something back


def test_the_block_choice_reeliminates_less_than_the_ratio_choice():
    """The point of the block: the same checks, each relinearising at most 30 variables, on a
    grid of 50 landmarks; GTSAM's own count of the variables each check re-eliminated, summed
    and at most, is far smaller when the 30 are neighbours in entry order."""
    header, records = simulate("grid", 1, landmarks=50)
    steps = group_steps(header, records)
    counts = {}
    for choice in ("ratio", "block"):
        smoother = Isam2Smoother(header, relinearize_skip=2, relinearize_max_variables=30, relinearize_choice=choice)
        recording = smoother._isam = _EntryOrder(smoother._isam)
        for step in steps:
            smoother.step(step)
        assert smoother.update_failures == 0
        counts[choice] = recording.reeliminated_in_checks
        smoother.finish()
        assert smoother.error() < 1.001 * batch_solve(smoother).final_error  # both end at the optimum
    assert len(counts["block"]) == len(counts["ratio"]) >= 50
    assert sum(counts["block"]) < 0.7 * sum(counts["ratio"])
    assert max(counts["block"]) < 0.6 * max(counts["ratio"])


def test_block_start_is_the_first_heaviest_window():
    assert block_start(np.array([1.0, 5.0, 0.0, 5.0, 1.0]), 2) == 0  # sums 6, 5, 5, 6: the first
    assert block_start(np.array([0.0, 0.0, 3.0, 4.0, 0.0]), 2) == 2
    assert block_start(np.array([2.0, 1.0]), 5) == 0  # fewer entries than the width
    assert block_start(np.array([2.0, 1.0]), 0) == 2  # an empty block: every entry outside it
    with pytest.raises(ValueError, match="choice"):
        CapChoice(0.01, 3, "nearest")
    with pytest.raises(FgslamError, match="relinearize_choice"):
        Isam2Smoother(simulate("arena-octagon", 1)[0], relinearize_choice="nearest")

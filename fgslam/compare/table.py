"""The metrics dictionary as a table: the terminal table and the rows the HTML report shows.

:func:`table_rows` formats the figures (metres to 0.1 mm, times in milliseconds), shows the
optional columns only when some run has them, and says what every column means
(:data:`COLUMN_MEANINGS`); :func:`format_table` lays them out in fixed width under one line
that says what the reference is (:func:`reference_line`).
"""

from __future__ import annotations

from fgslam.compare.metrics import estimator_names
from fgslam.compare.runs import describe_reference
from fgslam.failure import failed_cell


TABLE_HEADERS = (
    "estimator",
    "ATE final m",
    "ATE online m",
    "ATE aligned m",
    "final err m",
    "map RMSE m",
    "landmarks",
    "total ms",
    "step p50 ms",
    "step p99 ms",
)

#: The error columns' names when the reference is our own smoothed solution (no ground truth):
#: they measure agreement with the batch solution, not accuracy, and their names say so.
SMOOTHED_HEADERS = {
    "ATE final m": "vs ref final m",
    "ATE online m": "vs ref online m",
    "ATE aligned m": "vs ref aligned m",
    "final err m": "last pose vs ref m",
    "map RMSE m": "map vs ref m",
}

def _association_cell(m: dict) -> str:
    a = m.get("association")
    return "-" if a is None or a.get("rate") is None else f"{100 * a['rate']:.2f}"


def _association_counts_cell(m: dict) -> str:
    a = m.get("association")
    return "-" if a is None else f"{a.get('wrong', 0)}/{a.get('new', a.get('landmarks_created', 0))}/{a['rejected']}"


def _unused_cell(m: dict) -> str:
    u = m.get("unused_observations")
    if u is None:
        return "-"
    return " ".join(f"{v} {k}" for k, v in u.items() if v) or "0"


#: (header, metrics key, cell formatter) of the columns shown only when some run has them.
OPTIONAL_COLUMNS = (
    ("height RMSE m", "map_height_rmse_m", lambda m: _fmt(m.get("map_height_rmse_m"))),
    ("assoc %", "association", _association_cell),
    ("assoc wrong/new/rej", "association", _association_counts_cell),
    ("unused obs", "unused_observations", _unused_cell),
    ("NEES in %", "nees_inside_95", lambda m: _in_band_cell(m, "nees")),
    ("NIS in %", "nis_inside_95", lambda m: _in_band_cell(m, "nis")),
    ("peak MB", "peak_memory_mb", lambda m: _fmt(m.get("peak_memory_mb"), 1.0, 1)),
)

COLUMN_MEANINGS = {
    "ATE final m": "absolute trajectory error, metres: RMS position error of every pose as "
    "estimated after the last step",
    "ATE online m": "RMS position error, metres, of each pose as estimated at its own step "
    "(what the robot knew live); - for a one-shot batch solve",
    "ATE aligned m": "ATE final after the least-squares SE(2) alignment to the reference (what evo's -a "
    "and the TUM benchmark report): a map's frame is fixed only by its start pose, and a heading error "
    "made before the first landmark is seen turns the whole map; the gap to ATE final is that turn",
    "final err m": "position error of the last pose (the last pose with ground truth when the "
    "truth has gaps), metres",
    "map RMSE m": "RMS landmark position error, metres, over the landmark ids both maps contain "
    "(against the log's surveyed landmarks whenever it has them)",
    "landmarks": "number of landmarks the estimator mapped",
    "total ms": "wall-clock time of the whole run, milliseconds",
    "step p50 ms": "median wall-clock time per step, milliseconds; - for a one-shot batch solve",
    "step p99 ms": "99th-percentile wall-clock time per step, milliseconds; - for a one-shot "
    "batch solve",
    "height RMSE m": "RMS error of the landmark heights, metres, for estimators with a 3-D map",
    "assoc %": "share of observations associated with the right landmark, for estimators that "
    "associate observations themselves (rejected ones count as wrong)",
    "assoc wrong/new/rej": "observations associated with the wrong landmark (or a duplicate), "
    "landmarks the estimator created, and observations it rejected (left unused), scored "
    "against the log's truth_landmark_id",
    "unused obs": "observations the estimator did not use, by reason, from its own counters: "
    "skipped (no id and no association), rejected (ambiguous), unconfirmed (a new landmark's "
    "first sighting no later one agreed with), gated (outside the gate of its id), dropped "
    "(withheld after a failed update); 0 when it used every observation",
    "NEES in %": "share of steps whose NEES (online pose error against ground truth, weighted by "
    "the covariance the estimator stated) lies inside the 95 % chi-square(3) band; about 95 for "
    "a consistent estimator, less when it is over-confident (only with ground truth, over the "
    "steps that have it; against a truth without heading, like GPS, the position's NEES and the "
    "chi-square(2) band)",
    "NIS in %": "share of observations of already mapped landmarks whose NIS (innovation against "
    "the estimator's prediction, weighted by its predicted covariance) lies inside the 95 % "
    "chi-square(2) band (chi-square(1) for a range-only reading); about 95 when consistent; needs no ground truth. "
    "Both in % columns are taken at a seeded sample of steps by default (±: the share's standard "
    "error; fgslam run --consistency all: every step)",
    "peak MB": "how far the process's resident memory rose during the run, megabytes (10^6 bytes)",
    "vs ref final m": "no ground truth: RMS distance, metres, of every pose as estimated after the last step "
    "to the smoothed reference (the batch solution of the same log) - how far the estimator agrees with our "
    "own smoother, not its accuracy (the batch solution has errors of its own that no figure here shows)",
    "vs ref online m": "RMS distance, metres, of each pose as estimated at its own step (what the robot knew "
    "live) to the smoothed reference; - for a one-shot batch solve",
    "vs ref aligned m": "vs ref final after the least-squares SE(2) alignment to the smoothed reference",
    "last pose vs ref m": "distance of the last pose to the smoothed reference's last pose, metres",
    "map vs ref m": "RMS distance, metres, of the landmarks to the smoothed reference's map, over the ids "
    "both maps contain",
}


def _fmt(value, scale: float = 1.0, digits: int = 4) -> str:
    return "-" if value is None else f"{value * scale:.{digits}f}"


def _sampled(m: dict) -> bool:
    return (m.get("consistency") or {}).get("mode") == "sampled"


def _in_band_cell(m: dict, what: str) -> str:
    """The in-band share in per cent; ``±`` its standard error when taken at a sample of steps."""
    cell = _fmt(m.get(f"{what}_inside_95"), 100.0, 1)
    se = m.get(f"{what}_inside_95_se")
    return f"{cell}±{100 * se:.1f}" if _sampled(m) and se is not None and cell != "-" else cell


def sample_note(metrics: dict, names, shown: tuple[str, ...] = ("NEES", "NIS")) -> str | None:
    """The line under the table saying the NEES and NIS (those of ``shown``: the table's
    columns) come from a sample of steps, and how many (None when they were taken at every
    step, or not at all)."""
    for name in names:
        c = metrics[name].get("consistency") if isinstance(metrics[name], dict) else None
        if c and c.get("mode") == "sampled":
            counts = " and ".join(f"{what} at {c[what.lower() + '_steps']}" for what in shown)
            return (f"{' and '.join(shown)} in % at a seeded sample of steps (the same for every estimator): "
                    f"{counts} of {c['steps']} steps; ± is the share's standard error; --consistency all takes "
                    "every step")
    return None


def _consistency_notes(name: str, m: dict) -> list[str]:
    """A line when an estimator's mean NIS or NEES is more than 2× or less than half what a
    consistent estimator's would be (its degrees of freedom): which way it is off. (Its
    values are correlated from step to step, so a χ² band for the mean of independent values
    would be far too narrow; the table's "in %" columns give each value's own band.)"""
    from fgslam.verdict import FITS

    out = []
    for what, mean_key, count_key, dof_key in (("NIS", "nis_mean", "nis_count", "nis_dof"),
                                               ("NEES", "nees_mean", "nees_count", "nees_dof")):
        mean, count, dof = m.get(mean_key), m.get(count_key), m.get(dof_key)
        if mean is None or not count or not dof or FITS[0] <= mean / dof <= FITS[1]:
            continue
        factor = (mean / dof) ** 0.5
        if mean > dof:
            way = (f"its errors are ~{factor:.1f}x what it predicts: over-confident (stated noise too small, "
                   "or a model error)")
        else:
            way = f"its errors are ~{1 / factor:.1f}x smaller than it predicts: under-confident (stated noise too large)"
        out.append(f"{name}: mean {what} {mean:.2f} where a consistent estimator's is {dof:g}: {way}")
    return out


def reference_description(metrics: dict) -> str:
    """:func:`describe_reference` of a metrics dictionary (older dictionaries without the
    truth counts read as full ground truth or the smoothed solution, as they meant)."""
    kind = metrics.get("reference")
    poses = int(metrics.get("poses") or 0)
    with_truth = metrics.get("reference_poses_with_truth")
    if with_truth is None:
        with_truth = poses if kind == "ground_truth" else 0
    landmark_reference = metrics.get("landmark_reference", kind)
    return describe_reference(
        str(kind), poses=poses, poses_with_truth=int(with_truth), landmark_reference=landmark_reference,
        landmarks=int(metrics.get("reference_landmarks") or 0),
    )


def reference_line(metrics: dict) -> str:
    """One sentence saying what the figures are measured against.

    ``Reference: ground truth recorded in the log - run.jsonl, 660 poses`` with full truth;
    with gaps ``Reference: ground truth recorded in the log, 1981 of 2238 poses (gaps in the
    truth: 257 poses without truth are not scored) - r1.jsonl``.
    """
    what = reference_description(metrics)
    poses = metrics.get("poses")
    with_truth = metrics.get("reference_poses_with_truth")
    if metrics.get("reference") == "ground_truth" and with_truth is not None and with_truth != poses:
        return f"Reference: {what} - {metrics.get('log')}"  # the counts are in the description
    return f"Reference: {what} - {metrics.get('log')}, {poses} poses"


def table_rows(metrics: dict) -> tuple[tuple[str, ...], list[tuple[str, ...]], list[str]]:
    """The table shared by :func:`format_table` and the HTML report.

    Returns ``(headers, rows, notes)``: ``rows`` hold formatted strings (metres to 0.1 mm,
    times in milliseconds, ``-`` for "not applicable"); an ``*`` after an ATE means the
    estimate was aligned in SE(2); ``notes`` explain the marks that occur. The row of an
    estimator that failed mid-run has two cells, its name and ``failed at step N (t = ...
    s): <reason>`` (it has no figures).
    """
    names = estimator_names(metrics)
    # Columns that only matter for some runs appear only when some estimator has them.
    optional = [
        (header, cell)
        for header, key, cell in OPTIONAL_COLUMNS
        if any(metrics[n].get(key) is not None for n in names)
    ]
    rows = []
    notes = []
    any_aligned = False
    batch_is_reference = metrics.get("reference") == "smoothed"
    for name in names:
        m = metrics[name]
        failed_text = failed_cell(name, m)
        if failed_text is not None:
            rows.append((name, failed_text))
            continue
        star = "*" if m.get("aligned") else ""
        any_aligned |= bool(m.get("aligned"))
        if name == "batch" and batch_is_reference:  # the reference itself: nothing to score
            rows.append((
                "batch (reference)", "ref", "-", "ref", "ref", "ref" if not metrics.get("reference_landmarks") or
                metrics.get("landmark_reference") == "smoothed" else _fmt(m.get("map_rmse_m")),
                str(m.get("landmarks_estimated")), _fmt(m.get("time_total_s"), 1e3, 1), "-", "-",
                *(cell(m) for _, cell in optional),
            ))
            continue
        failed = m.get("failure")
        rows.append(
            (
                name,
                ("failed" if failed else _fmt(m.get("ate_rmse_m"))) + star,
                _fmt(m.get("ate_online_rmse_m")) + (star if m.get("ate_online_rmse_m") is not None else ""),
                _fmt(m.get("ate_aligned_rmse_m")),
                _fmt(m.get("final_pose_error_m")),
                _fmt(m.get("map_rmse_m")),
                str(m.get("landmarks_estimated")),
                _fmt(m.get("time_total_s"), 1e3, 1),
                _fmt(m.get("time_step_p50_s"), 1e3, 3),
                _fmt(m.get("time_step_p99_s"), 1e3, 3),
                *(cell(m) for _, cell in optional),
            )
        )
        if failed:
            notes.append(f"{name} failed: {failed}")
        if m.get("steps") != metrics.get("poses"):
            notes.append(f"{name} estimated {m.get('steps')} of {metrics.get('poses')} poses")
        if m.get("landmarks_estimated") == 0 and name not in ("dead_reckoning",) and metrics.get("reference_landmarks"):
            notes.append(f"{name} mapped no landmark (its map error is -): no observation it could use")
        notes += _consistency_notes(name, m)
    if any_aligned:
        notes.insert(0, "* aligned to the reference in SE(2) (first poses differ)")
    in_band = tuple(what for what in ("NEES", "NIS") if any(h == f"{what} in %" for h, _ in optional))
    if in_band:
        note = sample_note(metrics, names, in_band)
        if note:
            notes.append(note)
    if batch_is_reference:
        notes.insert(0, "no ground truth: every error above is the distance to the smoothed solution (batch, the "
                        "reference) - agreement with it, not accuracy")
    headers = _reference_headers(metrics) + tuple(header for header, _ in optional)
    return headers, rows, notes


def _reference_headers(metrics: dict) -> tuple[str, ...]:
    """:data:`TABLE_HEADERS`, with the error columns named "vs ref" when what they are measured
    against is the smoothed solution (the map's column only when the map is too: surveyed
    landmarks keep "map RMSE m")."""
    if metrics.get("reference") != "smoothed":
        return TABLE_HEADERS
    map_smoothed = metrics.get("landmark_reference", "smoothed") in (None, "smoothed")
    return tuple(
        SMOOTHED_HEADERS[h] if h in SMOOTHED_HEADERS and (h != "map RMSE m" or map_smoothed) else h
        for h in TABLE_HEADERS
    )


def format_table(metrics: dict) -> str:
    """A fixed-width terminal table of :func:`compute_metrics` output.

    First line: what the reference is. Then one row per estimator with ATE final, ATE
    online, final pose error, map RMSE (metres), landmark count, and total / median /
    99th-percentile step time (milliseconds). ``-`` means not applicable.
    """
    headers, rows, notes = table_rows(metrics)
    full = [r for r in rows if len(r) == len(headers)]  # a failed estimator's row is its name and one sentence
    widths = [max(len(h), *(len(r[i]) for r in full)) if full else len(h) for i, h in enumerate(headers)]
    widths[0] = max(widths[0], *(len(r[0]) for r in rows)) if rows else widths[0]

    def line(cells) -> str:
        first = cells[0].ljust(widths[0])
        if len(cells) < len(widths):
            return "  ".join([first, *cells[1:]]).rstrip()
        rest = [c.rjust(w) for c, w in zip(cells[1:], widths[1:])]
        return "  ".join([first, *rest]).rstrip()

    out = [reference_line(metrics), line(headers), line(["-" * w for w in widths])]
    out += [line(r) for r in rows]
    out += notes
    return "\n".join(out)

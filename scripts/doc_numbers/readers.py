"""Readers: from a source's result (a metrics dictionary, a script's table) to one number in
the doc's unit. ``metric_row`` builds the quotes of a line of fgslam's comparison table."""

from __future__ import annotations

from scripts.doc_numbers.quotes import Quote, numbers_in, parse_number, row


def metric(estimator: str, key: str, scale: float = 1.0):
    """``result[estimator][key] × scale``."""
    return lambda result: result[estimator][key] * scale


def unused(estimator: str):
    """The table's "unused obs" column as a number: every skipped, rejected or gated one."""
    return lambda result: sum(result[estimator]["unused_observations"].values())


def association_rate(estimator: str):
    return lambda result: 100 * result[estimator]["association"]["rate"]


def association(estimator: str, key: str):
    return lambda result: result[estimator]["association"][key]


#: A column of fgslam's comparison table (``fgslam run``'s terminal table) → its reader.
COLUMNS = {
    "ate": lambda e: metric(e, "ate_rmse_m"),
    "online": lambda e: metric(e, "ate_online_rmse_m"),
    "aligned": lambda e: metric(e, "ate_aligned_rmse_m"),
    "final": lambda e: metric(e, "final_pose_error_m"),
    "map": lambda e: metric(e, "map_rmse_m"),
    "landmarks": lambda e: metric(e, "landmarks_estimated"),
    "unused": unused,
    "nees": lambda e: metric(e, "nees_inside_95", 100),
    "nis": lambda e: metric(e, "nis_inside_95", 100),
    "assoc": association_rate,
}


def metric_row(doc: str, text: str, source: str, estimator: str, columns: str) -> list[Quote]:
    """The quotes of one line ``text`` of a comparison table printed by ``fgslam run``.
    ``columns`` names each number of the line in order (space-separated :data:`COLUMNS`
    keys; ``-`` for a number not checked, such as a time)."""
    names = columns.split()
    cells = {i: COLUMNS[name](estimator) for i, name in enumerate(names) if name != "-"}
    return row(doc, text, source, f"{estimator} row", cells)


def table_cell(first_cell: str, index: int):
    """Number ``index`` (counting from 0) of the row of a script's markdown table whose first
    cell is ``first_cell``; the source's result maps first cells to their numbers."""
    return lambda result: result[first_cell][index]


def markdown_rows(table: str) -> dict[str, list[str]]:
    """A markdown table printed by a script → first cell → the numbers of its row
    (:func:`~doc_numbers.quotes.numbers_in`)."""
    rows, body = {}, False
    for line in table.splitlines():
        cells = line.split("|")
        if line.startswith("|---"):  # the rows after the separator; the header's numbers are names
            body = True
        elif body and line.startswith("|") and len(cells) > 2:
            rows[cells[1].strip()] = numbers_in(line)
    return rows


def same_row(doc: str, text: str, source: str, label: str) -> list[Quote]:
    """Every number of the markdown row ``text`` against the same row (same first cell) of the
    table the source printed, number by number."""
    first = text.split("|")[1].strip()
    return row(doc, text, source, f"{label} {first}",
               {i: (lambda result, i=i: parse_number(result[first][i])) for i in range(len(numbers_in(text)))})


def scene(scenario: str, read):
    """``read`` applied to one scenario's result of a source that runs several."""
    return lambda result: read(result[scenario])


def flaw(log: str, setting: str, key: str = "ate_rmse_m"):
    """One setting of ``scripts/flaw_costs.py`` on one log (the ``flaw-costs`` source)."""
    return lambda result: result[log][setting][key]


def item(key, index: int):
    """``result[key][index]``: one number of a tuple a source keeps per row or per setting."""
    return lambda result: result[key][index]


def median(values) -> float:
    import statistics

    return statistics.median(values)

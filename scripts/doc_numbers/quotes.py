"""A number quoted in a doc, the measurement that recomputes it, and their comparison.

A :class:`Quote` names the doc, the exact text around the number (so the check fails when
the doc changes the number without the registry, too), which number of that text it is, the
:class:`Source` that measures it, and how to read the measured value from the source's
result. A source runs once per check, however many quotes it feeds.

The tolerance is absolute, in the doc's unit; by default half a unit of the last digit
quoted (0.0110 m: ±0.00005 m), i.e. the measured value must round to the quoted one.
"""

from __future__ import annotations

import math
import re
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

ROOT = Path(__file__).resolve().parents[2]

#: A number as docs write it: an optional minus (ASCII or U+2212), digits, an optional decimal
#: part; not part of a word (``s001``) or of a longer number. Thousands are grouped by a
#: space ("6 621 poses"): a group of 1-3 digits followed by space-separated groups of 3 is one number.
NUMBER = re.compile(r"(?<![\w.])[-\u2212]?(?:\d{1,3}(?: \d{3})+(?!\d|\.\d)|\d+(?:\.\d+)?(?!\d))")

#: How expensive a source is. ``cheap``: seconds (the quick test suite runs it); ``slow``:
#: up to a few minutes (CI runs it, ``@pytest.mark.slow``); ``long``: longer than CI can
#: afford (only ``python -m scripts.check_doc_numbers --long``).
COSTS = ("cheap", "slow", "long")


@dataclass
class Context:
    """Where a measurement finds its inputs: the repository, the shared data folder (or None)
    and a scratch folder for the logs it writes."""

    root: Path
    shared: Path | None
    scratch: Path


@dataclass(frozen=True)
class Source:
    """One measurement. ``measure(context)`` returns anything the quotes' readers understand
    (usually a metrics dictionary); ``command`` is what a reader would run to see the same;
    ``shared`` is the path under the shared data folder it needs (None: nothing)."""

    name: str
    command: str
    cost: str
    measure: Callable[[Context], Any]
    shared: str | None = None

    def __post_init__(self):
        if self.cost not in COSTS:
            raise ValueError(f"{self.name}: cost must be one of {COSTS}, not {self.cost!r}")


@dataclass(frozen=True)
class Quote:
    """One number in one doc. ``text`` is an exact substring of the doc, ``number`` the number
    as written there (its ``nth`` occurrence in ``text`` as a whole number), ``read`` turns the
    source's result into the measured value in the doc's unit."""

    doc: str
    text: str
    number: str
    source: str
    read: Callable[[Any], float]
    label: str
    nth: int = 0
    tolerance: float | None = None

    def quoted_value(self) -> float:
        return parse_number(self.number)

    def allowed(self) -> float:
        """The absolute tolerance: given, or half a unit of the last quoted digit."""
        if self.tolerance is not None:
            return self.tolerance
        decimals = len(self.number.split(".")[1]) if "." in self.number else 0
        return 0.5 * 10.0**-decimals * (1 + 1e-9)


@dataclass
class Outcome:
    quote: Quote
    status: str  # "ok", "MISMATCH", "NOT IN DOC", "ERROR", "skipped"
    measured: float | None = None
    reason: str = ""

    @property
    def failed(self) -> bool:
        return self.status not in ("ok", "skipped")


def parse_number(text: str) -> float:
    return float(text.replace("\u2212", "-").replace(" ", ""))


def numbers_in(text: str) -> list[str]:
    """The whole numbers of ``text`` in order, as written."""
    return NUMBER.findall(text)


def quote_in_doc(quote: Quote, root: Path = ROOT) -> str:
    """"" when ``quote`` is where the registry says; else what is wrong."""
    path = root / quote.doc
    if not path.is_file():
        return f"{quote.doc} does not exist"
    if quote.text not in path.read_text(encoding="utf-8"):
        return f"text not in {quote.doc}: {quote.text!r}"
    if numbers_in(quote.text).count(quote.number) <= quote.nth:
        return f"{quote.number} does not occur {quote.nth + 1} time(s) in {quote.text!r}"
    return ""


def row(doc: str, text: str, source: str, label: str, cells: dict[int, Callable[[Any], float]],
        tolerance: float | None = None) -> list[Quote]:
    """Quotes for several numbers of one line of a table: ``cells`` maps the index of a number
    in ``text`` (:func:`numbers_in`, counting from 0) to its reader."""
    numbers = numbers_in(text)
    quotes = []
    for index, read in cells.items():
        number = numbers[index]
        quotes.append(Quote(doc, text, number, source, read, f"{label} #{index}",
                            nth=numbers[:index].count(number), tolerance=tolerance))
    return quotes


@dataclass
class Checker:
    """Runs sources on demand (each once) and compares every quote with its measurement."""

    sources: dict[str, Source]
    context: Context
    costs: tuple[str, ...] = ("cheap", "slow")
    results: dict[str, Any] = field(default_factory=dict)
    errors: dict[str, str] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)

    def skip_reason(self, source: Source) -> str:
        if source.shared is not None:
            if self.context.shared is None:
                return f"needs the shared data ({source.shared}): give --shared FOLDER"
            if not (self.context.shared / source.shared).exists():
                return f"{self.context.shared / source.shared} not found"
        if source.cost not in self.costs:
            return f"{source.cost} (run with --{source.cost})" if source.cost == "long" else source.cost
        return ""

    def result(self, source: Source) -> Any:
        if source.name not in self.results and source.name not in self.errors:
            start = time.perf_counter()
            try:
                self.results[source.name] = source.measure(self.context)
            except Exception as error:  # noqa: BLE001 - reported as the quote's outcome
                self.errors[source.name] = f"{type(error).__name__}: {error}\n{traceback.format_exc()}"
            self.seconds[source.name] = time.perf_counter() - start
        return self.results.get(source.name)

    def check(self, quote: Quote) -> Outcome:
        problem = quote_in_doc(quote, self.context.root)
        if problem:
            return Outcome(quote, "NOT IN DOC", reason=problem)
        source = self.sources[quote.source]
        reason = self.skip_reason(source)
        if reason:
            return Outcome(quote, "skipped", reason=reason)
        result = self.result(source)
        if source.name in self.errors:
            return Outcome(quote, "ERROR", reason=self.errors[source.name].splitlines()[0])
        try:
            measured = float(quote.read(result))
        except Exception as error:  # noqa: BLE001
            return Outcome(quote, "ERROR", reason=f"reading the result: {type(error).__name__}: {error}")
        if not math.isfinite(measured) or abs(measured - quote.quoted_value()) > quote.allowed():
            return Outcome(quote, "MISMATCH", measured)
        return Outcome(quote, "ok", measured)


def format_outcomes(outcomes: list[Outcome], sources: dict[str, Source]) -> str:
    """The table quoted vs measured, one line per quote, then what was skipped and why."""
    lines = [f"{'status':<10}  {'doc':<18}  {'quoted':>10}  {'measured':>12}  {'tolerance':>9}  label / source"]
    for o in outcomes:
        if o.status == "skipped":
            continue
        measured = "-" if o.measured is None else f"{o.measured:.6g}"
        lines.append(f"{o.status:<10}  {o.quote.doc:<18}  {o.quote.number:>10}  {measured:>12}  "
                     f"{o.quote.allowed():>9.2g}  {o.quote.label} [{o.quote.source}]")
        if o.reason:
            lines.append(f"{'':<12}{o.reason}")
    skipped: dict[str, tuple[int, str]] = {}
    for o in outcomes:
        if o.status == "skipped":
            count, _ = skipped.get(o.quote.source, (0, ""))
            skipped[o.quote.source] = (count + 1, o.reason)
    for name, (count, reason) in skipped.items():
        lines.append(f"skipped     {count:>3} quote(s) of {name} ({sources[name].command}): {reason}")
    counts: dict[str, int] = {}
    for o in outcomes:
        counts[o.status] = counts.get(o.status, 0) + 1
    lines.append(", ".join(f"{n} {s}" for s, n in sorted(counts.items())))
    return "\n".join(lines)

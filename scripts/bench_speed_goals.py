"""Benchmark: every speed goal of issue 43 measured on each log in one run, one table.

For each log, in one process with BLAS on one thread, this calls the measuring functions of
the benchmarks that each goal came from and prints one row per figure: measured / goal /
met? (``—`` where no goal is stated for that log). Times are CPU times (the machine is
shared), the best (smallest) of ``--repeats`` runs:

1. :func:`scripts.bench_reader.measure` (``cpu=True``): ``read_log`` against a plain
   ``json.loads`` loop over the lines (≤ 1.0×), ``fgslam validate`` as a child process,
   start-up included, against the loop in this process (≤ 1.2×) and against the loop run as
   a child (no goal: on a small log the first ratio is mostly start-up), and validate's
   peak RSS (≤ 150 MB);
2. :func:`scripts.bench_python_share.timed_run`: Python's share of the default ``isam2``'s
   CPU (≤ 10 %);
3. :func:`scripts.bench_consistency_cost.measure`, ``fgslam run``'s default estimators with
   no consistency work and with it at the default sample: the NIS/NEES work's share of the
   estimators' own CPU (≤ 10 %), and the default isam2's total over the EKF's, by CPU, of a
   default run (≤ 2.1 on Victoria Park, ≤ 3.7 on Plaza1, ≤ 1.45 on an MRCLAM robot; the goal
   is taken from the log's name);
4. :func:`scripts.bench_long_steps.timed_run`: the default isam2's longest single step by
   CPU (≤ 33 ms; ≤ 50 ms on ``grid:2000``) and its p99 (no goal here);
5. a 3-D log only: :func:`scripts.bench_vio.full_run`, the whole default ``fgslam run``
   pipeline (no report) by CPU (≤ 60 s; the wall time beside it; the CPU includes the
   memory poll's, ~0.1 %) and the process's peak resident size, polled every 20 ms
   (:class:`ResidentPoll`; ≤ 500 MB).

Logs: a run log's path (planar or 3-D, as ``fgslam import`` writes it), ``victoria-park``,
``plaza1``, ``plaza2``, ``mrclam:FOLDER:R1,R2``, ``mrclam-fitted:FOLDER:R1,R2``,
``arena:A-B`` (``scripts/bench_online.py``'s sources), ``grid:N[:LAPS]``
(``scripts/bench_long_steps.py``'s), ``seed003:NAME`` or ``long-sim[:SEED]`` (3-D,
``scripts/bench_vio.py``'s). A named planar source is written to a temporary run log
(parts 1 and 3 read a file).

Usage::

    .venv/bin/python -m scripts.bench_speed_goals victoria-park.jsonl plaza1.jsonl mrclam-robot1.jsonl
    .venv/bin/python -m scripts.bench_speed_goals victoria-park long-sim --parts 2,3,5 --repeats 2
"""

from __future__ import annotations

from scripts.common import one_blas_thread, print_table_head, print_table_row

one_blas_thread()

import argparse  # noqa: E402
import os  # noqa: E402
import tempfile  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from fgslam.memory import resident_kib  # noqa: E402
from fgslam.registry import DEFAULTS  # noqa: E402
from scripts import bench_consistency_cost, bench_long_steps, bench_python_share, bench_reader, bench_vio  # noqa: E402
from slamio.log import RunLog, group_steps, read_log, write_log  # noqa: E402

PARTS = (1, 2, 3, 4, 5)
#: The isam2 / EKF goal (total CPU of a default run) by a word of the log's name.
ISAM2_OVER_EKF = (("victoria", 2.1), ("plaza1", 3.7), ("mrclam", 1.45))


@dataclass(frozen=True)
class Row:
    """One figure of one log: its value against its goal (``None``: none stated)."""

    log: str
    part: int
    figure: str
    value: float
    unit: str
    goal: float | None

    def met(self) -> str:
        return "—" if self.goal is None else ("yes" if self.value <= self.goal else "**no**")

    def cells(self) -> tuple[str, ...]:
        digits = 2 if self.unit in ("×", "s") else 1
        goal = "—" if self.goal is None else f"≤ {self.goal:g} {self.unit}"
        return (self.log, str(self.part), self.figure, f"{self.value:.{digits}f} {self.unit}", goal, self.met())


def isam2_over_ekf_goal(name: str) -> float | None:
    lower = name.lower()
    return next((goal for word, goal in ISAM2_OVER_EKF if word in lower), None)


def longest_step_goal_ms(name: str) -> float:
    return 50.0 if name.replace(" ", "").startswith("grid:2000") else 33.0


def sources(spec: str, folder: str):
    """(name, log) of a command-line source; a named planar one written as a run log into ``folder``."""
    if spec.startswith(("seed003:", "long-sim")):
        yield bench_vio.load(spec)
    elif os.path.isfile(spec):
        yield os.path.basename(spec), read_log(spec)
    else:
        named = ([(spec, *bench_long_steps.load(spec))] if spec.startswith("grid:")
                 else bench_python_share.sources(spec))
        for name, header, records in named:
            path = Path(folder) / f"{len(os.listdir(folder))}.jsonl"
            write_log(path, header, records)
            yield name, RunLog(path=str(path), header=header, records=tuple(records))


def part1(name: str, log: RunLog, repeats: int) -> list[Row]:
    r = bench_reader.measure(str(log.path), repeats, cpu=True)
    return [Row(name, 1, "read_log / json.loads loop", r["read_x"], "×", 1.0),
            Row(name, 1, "fgslam validate / loop (start-up incl.)", r["validate_x"], "×", 1.2),
            Row(name, 1, "fgslam validate / loop as a child", r["validate_xc"], "×", None),
            Row(name, 1, "fgslam validate peak RSS", r["rss_MB"], "MB", 150.0)]


def part2(name: str, log: RunLog, repeats: int) -> list[Row]:
    steps = group_steps(log.header, log.records)
    total, gtsam_s = min((bench_python_share.timed_run(log.header, steps, {}) for _ in range(repeats)),
                         key=lambda run: run[0])
    return [Row(name, 2, "Python's share of isam2's CPU", 100.0 * (total - sum(gtsam_s.values())) / total, "%", 10.0)]


def part3(name: str, log: RunLog, repeats: int) -> list[Row]:
    names = DEFAULTS[2]
    cpu, _ = bench_consistency_cost.measure(str(log.path), names, repeats, ("default",), base_modes=("none",))
    own = sum(cpu[(n, "none")][0] for n in names)
    work = sum(cpu[(n, "default")][1] for n in names)
    ratio = cpu[("isam2", "default")][0] / cpu[("ekf", "default")][0]
    return [Row(name, 3, "NIS/NEES work / estimators' own CPU", 100.0 * work / own, "%", 10.0),
            Row(name, 3, "isam2 / EKF total CPU, default run", ratio, "×", isam2_over_ekf_goal(name))]


def part4(name: str, log: RunLog, repeats: int) -> list[Row]:
    steps = group_steps(log.header, log.records)
    step_ms = []
    for _ in range(repeats):
        _, events, _ = bench_long_steps.timed_run(log.header, steps, False)
        step_ms.append(1e3 * np.array(events.step_cpu_s))
    return [Row(name, 4, "isam2 longest step, CPU", min(float(ms.max()) for ms in step_ms), "ms",
                longest_step_goal_ms(name)),
            Row(name, 4, "isam2 p99 step, CPU", min(float(np.percentile(ms, 99)) for ms in step_ms), "ms", None)]


class ResidentPoll:
    """The process's largest resident size (MB) seen by a thread polling ``/proc`` every
    ``every_s`` while the ``with`` block runs (a lower bound: a shorter spike can fall between
    two polls). Not :class:`fgslam.memory.PeakMemory`: ``fgslam run`` resets the kernel's
    high-water mark before each estimator, so that would see only the last estimator's peak."""

    def __init__(self, every_s: float = 0.02):
        self.every_s, self._peak_kib = every_s, None
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._poll, daemon=True)

    @property
    def peak_mb(self) -> float:
        return float("nan") if self._peak_kib is None else self._peak_kib / 1024.0

    def _poll(self) -> None:
        while True:
            kib = resident_kib()
            if kib is not None:
                self._peak_kib = max(kib, self._peak_kib or 0)
            if self._done.wait(self.every_s):
                return

    def __enter__(self) -> "ResidentPoll":
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._done.set()
        self._thread.join()


def part5(name: str, log: RunLog, repeats: int) -> list[Row]:
    runs = []
    for _ in range(repeats):
        start = time.process_time()
        with ResidentPoll() as resident:
            wall, _ = bench_vio.full_run(log)
        runs.append((time.process_time() - start, wall, resident.peak_mb))
    cpu_s, wall_s, peak_mb = min(runs)
    return [Row(name, 5, "default 3-D fgslam run (no report), CPU", cpu_s, "s", 60.0),
            Row(name, 5, "the same, wall", wall_s, "s", None),
            Row(name, 5, "process peak resident size (polled)", peak_mb, "MB", 500.0)]


MEASURES = {1: part1, 2: part2, 3: part3, 4: part4, 5: part5}


def goal_rows(name: str, log: RunLog, parts, repeats: int) -> list[Row]:
    """Every row of one log for ``parts`` (a 3-D log: part 5 only; a planar one: parts 1–4)."""
    wanted = [p for p in parts if (p == 5) == log.header.is_3d]
    return [row for part in wanted for row in MEASURES[part](name, log, repeats)]


def parse_parts(text: str) -> list[int]:
    parts = sorted({int(p) for p in text.split(",") if p})
    if not set(parts) <= set(PARTS):
        raise argparse.ArgumentTypeError(f"parts are {', '.join(map(str, PARTS))}")
    return parts


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="+", metavar="LOG", help="run-log paths or named sources (module docstring)")
    ap.add_argument("--parts", type=parse_parts, default=list(PARTS), help="comma-separated, of 1-5 (default: all)")
    ap.add_argument("--repeats", type=int, default=1, help="each figure is the best of this many runs")
    args = ap.parse_args(argv)
    print(f"load average at the start: {os.getloadavg()[0]:.1f}", flush=True)
    rows: list[Row] = []
    with tempfile.TemporaryDirectory() as folder:
        for spec in args.logs:
            for name, log in sources(spec, folder):
                rows += goal_rows(name, log, args.parts, args.repeats)
                print(f"measured {name}", flush=True)
    print(f"load average at the end: {os.getloadavg()[0]:.1f}\n")
    print_table_head("log", "part", "figure", "measured", "goal", "met?")
    for row in rows:
        print_table_row(*row.cells())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

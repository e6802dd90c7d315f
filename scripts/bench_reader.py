"""Benchmark: reading a run log against a plain ``json.loads`` loop over its lines (issue 43).

For each log, in this one process on the same file (each timing the best of ``--repeat``):
the ``json.loads`` loop (``for line in f: json.loads(line)``), :func:`slamio.log.read_log`
(parse + validate, every record kept) and :func:`slamio.log.iter_log` (streamed), each as a
ratio to the loop; then ``fgslam validate LOG`` as a child process (start-up included), its
wall time as a ratio to the loop and its peak RSS (``resource.getrusage`` of the child), and
as a ratio to the same loop run as a child process (``python -c``: start-up included on both
sides, ``validate_xc``; on a small log the in-process ratio is mostly Python's and numpy's
start-up). Goals: read ≤ 1.0×, validate ≤ 1.2×, validate ≤ 150 MB RSS.

A large log to measure on (80 MB, 2 700 landmarks driven twice)::

    fgslam sim grid --landmarks 2700 --laps 2 --out /tmp/big.jsonl

Usage::

    .venv/bin/python -m scripts.bench_reader /tmp/big.jsonl [LOG ...] [--repeat 3]
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import resource
import subprocess
import sys
import time
from typing import Callable


def json_loop(path: str) -> None:
    with open(path, "rb") as f:
        for line in f:
            json.loads(line)


def read_all(path: str) -> None:
    from slamio.log import read_log

    read_log(path)


def stream(path: str) -> None:
    from slamio.log import iter_log

    collections.deque(iter_log(path), maxlen=0)


def children_cpu_s() -> float:
    """User + system CPU time (s) of every child process waited for so far (their children included)."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def best_of(repeat: int, work: Callable[[], object], clock: Callable[[], float] = time.perf_counter) -> float:
    """The shortest time on ``clock`` (default: wall) of ``repeat`` runs of ``work`` (s)."""
    times = []
    for _ in range(repeat):
        start = clock()
        work()
        times.append(clock() - start)
    return min(times)


#: Runs a command and prints its peak RSS in kB. A small process of its own, because a
#: child's ru_maxrss counts the pages it shares with its parent between fork and exec.
_PEAK_RSS = (
    "import resource, subprocess, sys; subprocess.run(sys.argv[1:], check=True, stdout=subprocess.DEVNULL); "
    "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)"
)


def validate_child(path: str, clock: Callable[[], float] = time.perf_counter) -> tuple[float, float]:
    """(time in s, peak RSS in MB) of ``fgslam validate path`` in a child process (the time,
    wall or the children's CPU (:func:`children_cpu_s`), includes a small wrapper's start-up,
    ~20 ms, which only counts against it)."""
    fgslam = os.path.join(os.path.dirname(sys.executable), "fgslam")
    start = clock()
    done = subprocess.run([sys.executable, "-c", _PEAK_RSS, fgslam, "validate", path], check=True,
                          capture_output=True, text=True)
    elapsed = clock() - start
    return elapsed, int(done.stdout.split()[-1]) / 1024.0  # Linux: kB


_JSON_LOOP = "import json, sys\nwith open(sys.argv[1], 'rb') as f:\n    for line in f:\n        json.loads(line)"


def json_loop_child(path: str, clock: Callable[[], float] = time.perf_counter) -> float:
    """Time (s) of the ``json.loads`` loop as a child ``python -c`` (start-up included),
    through the same wrapper as :func:`validate_child`."""
    start = clock()
    subprocess.run([sys.executable, "-c", _PEAK_RSS, sys.executable, "-c", _JSON_LOOP, path], check=True,
                   capture_output=True)
    return clock() - start


def measure(path: str, repeat: int, cpu: bool = False) -> dict[str, float]:
    """The figures of one log (``main``'s columns); ``cpu``: CPU time (this process's, and
    the children's for ``fgslam validate`` and the child loop) in place of wall time."""
    clock, child_clock = (time.process_time, children_cpu_s) if cpu else (time.perf_counter, time.perf_counter)
    loop = best_of(repeat, lambda: json_loop(path), clock)
    read = best_of(repeat, lambda: read_all(path), clock)
    streamed = best_of(repeat, lambda: stream(path), clock)
    runs = [validate_child(path, child_clock) for _ in range(repeat)]
    validate = min(t for t, _ in runs)
    rss = max(r for _, r in runs)
    loop_child = min(json_loop_child(path, child_clock) for _ in range(repeat))
    return {"MB": os.path.getsize(path) / 1e6, "json_s": loop, "read_s": read, "read_x": read / loop,
            "iter_s": streamed, "iter_x": streamed / loop, "validate_s": validate, "validate_x": validate / loop,
            "validate_xc": validate / loop_child, "rss_MB": rss}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("logs", nargs="+", metavar="LOG")
    parser.add_argument("--repeat", type=int, default=3, help="timings are the best of this many runs")
    args = parser.parse_args(argv)
    columns = ("MB", "json_s", "read_s", "read_x", "iter_s", "iter_x", "validate_s", "validate_x", "validate_xc",
               "rss_MB")
    print(f"{'log':<32}" + "".join(f"{c:>12}" for c in columns))
    for path in args.logs:
        row = measure(path, args.repeat)
        print(f"{os.path.basename(path):<32}" + "".join(f"{row[c]:>12.2f}" for c in columns), flush=True)
    print("goals: read_x <= 1.0 (parse + validate), validate_x <= 1.2 (start-up included), rss_MB <= 150; "
          "validate_xc: against the loop as a child process")
    return 0


if __name__ == "__main__":
    sys.exit(main())

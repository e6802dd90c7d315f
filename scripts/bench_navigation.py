"""Compare the navigators where the product runs them: ``fgslam live --port sim --world
clutter --navigate NAME`` in the clutter room of each seed, then ``fgslam run`` on the log
each produced (EKF against iSAM2).

    .venv/bin/python -m scripts.bench_navigation --work DIR [--seeds 1-10] [--duration 300]
        [--time-scale 20] [--jobs 2] [--figure docs/navigate_paths.png] [NAME ...]

Per run, from the log (truth poses, observations, event records) and from ``fgslam run``'s
``metrics.json``:

* ``bumps`` — event records of kind ``bump`` (each one stopped the wheels; the run went on);
* ``stuck_s`` — the longest time the robot's true position stayed within 0.1 m of one spot
  (turning in place counts as stuck), and ``area_m2`` — floor the robot's disc swept (0.25 m
  cells it overlapped): the harness's definitions (:mod:`fgslam.navigate.harness`);
* ``seen`` / ``revisited`` — landmarks observed at all, and observed again after 20 s of not
  being seen (a loop closure for the smoother), as shares of the room's tags;
* ``map_m`` / ``ate_m`` — map RMSE and trajectory ATE of the EKF and of iSAM2 (final and
  online) against the simulator's truth;
* ``isam2_p99_ms`` — the live smoother's 99th-percentile step (its ``live_step`` records),
  ``nav_p99_us`` — the navigator's, from the run's printed summary (wall clock, in the loop).

Each run's log and results stay in ``--work`` (a run already there is reused), so the numbers
can be checked. Every run is the same on any machine: the live loop runs in lockstep with
the simulated clock (fgslam/live/navigation.py).
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from fgslam.navigate.harness import longest_stuck_s, visited_area_m2
from slamio.log import Event, LiveStep, Observation, TruthPose, read_log

NAVIGATORS = ("vfh-s000", "vfh", "explore-s001", "explore")
REVISIT_GAP_S = 20.0
#: ``fgslam`` in this interpreter (the console script's entry point)
FGSLAM = [sys.executable, "-c", "import sys; from fgslam.cli import main; sys.exit(main(sys.argv[1:]))"]


def _seeds(text: str) -> list[int]:
    first, _, last = text.partition("-")
    return list(range(int(first), int(last or first) + 1))


def sightings(observations: list[Observation], gap_s: float = REVISIT_GAP_S) -> tuple[set[int], set[int]]:
    """(landmarks seen, landmarks seen again after ``gap_s`` of not being seen)."""
    last: dict[int, float] = {}
    revisited: set[int] = set()
    for o in observations:
        if o.landmark_id is None:
            continue
        if o.landmark_id in last and o.stamp_s - last[o.landmark_id] >= gap_s:
            revisited.add(o.landmark_id)
        last[o.landmark_id] = o.stamp_s
    return set(last), revisited


def _live(name: str, seed: int, args, log: Path) -> None:
    if log.exists():
        return
    command = [*FGSLAM, "live", "--port", "sim", "--world", "clutter", "--navigate", name,
               "--duration", str(args.duration), "--sim-seed", str(seed), "--sim-time-scale", str(args.time_scale),
               "--out", str(log)]
    done = subprocess.run(command, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} exited {done.returncode}:\n{done.stderr[-2000:]}")
    log.with_suffix(".out").write_text(done.stdout)  # its summary: the navigator's step times


def _compare(log: Path, out: Path) -> dict:
    if not (out / "metrics.json").exists():
        subprocess.run([*FGSLAM, "run", str(log), "--out", str(out), "--estimators",
                        "ekf,isam2", "--overwrite"], capture_output=True, text=True, check=True)
    return json.loads((out / "metrics.json").read_text())


def one_run(name: str, seed: int, args) -> dict:
    work = Path(args.work)
    log = work / f"{name}_{seed:02d}.jsonl"
    _live(name, seed, args, log)
    metrics = _compare(log, work / f"{name}_{seed:02d}")
    records = read_log(log).records
    truth = [r for r in records if isinstance(r, TruthPose)]
    stamps = np.array([t.stamp_s for t in truth])
    xy = np.array([[t.x_m, t.y_m] for t in truth])
    from slamio.clutter import clutter_world

    tags = {t.tag_id for t in clutter_world(seed).tags}
    seen, revisited = sightings([r for r in records if isinstance(r, Observation)])
    return {
        "navigator": name, "seed": seed,
        "bumps": sum(isinstance(r, Event) and r.kind == "bump" for r in records),
        "stuck_s": longest_stuck_s(stamps, xy), "area_m2": visited_area_m2(xy),
        "seen": len(seen & tags) / len(tags), "revisited": len(revisited & tags) / len(tags),
        "ekf_ate_m": metrics["ekf"]["ate_rmse_m"], "isam2_ate_m": metrics["isam2"]["ate_rmse_m"],
        "isam2_online_ate_m": metrics["isam2"]["ate_online_rmse_m"],
        "ekf_map_m": metrics["ekf"]["map_rmse_m"], "isam2_map_m": metrics["isam2"]["map_rmse_m"],
        "isam2_p99_ms": 1e3 * float(np.percentile([r.latency_s for r in records if isinstance(r, LiveStep)], 99)),
        "nav_p99_us": _navigator_p99_us(log.with_suffix(".out")),
        "path": xy,
    }


def _navigator_p99_us(summary: Path) -> float:
    """The navigator's p99 step (wall, in the live loop) from the run's printed summary; nan
    when the summary was not kept."""
    import re

    if not summary.exists():
        return math.nan
    found = re.search(r"navigator: \d+ steps, median \d+ µs, p99 (\d+) µs", summary.read_text())
    return float(found.group(1)) if found else math.nan


def _print(rows: list[dict]) -> None:
    head = ("navigator", "seed", "bumps", "stuck_s", "area_m2", "seen", "revisited", "ekf_ate_m", "isam2_ate_m",
            "isam2_online_ate_m", "ekf_map_m", "isam2_map_m", "isam2_p99_ms", "nav_p99_us")
    print(" ".join(f"{h:>12s}" for h in head))
    for r in rows:
        print(" ".join(f"{r[h]:>12}" if isinstance(r[h], (str, int)) else f"{r[h]:12.3f}" for h in head))
    print("\nper navigator over the seeds: bumps total (runs with any), longest stuck, median seen / revisited, "
          "median ATE EKF / iSAM2, median map EKF / iSAM2")
    for name in dict.fromkeys(r["navigator"] for r in rows):
        mine = [r for r in rows if r["navigator"] == name]
        med = {k: float(np.median([r[k] for r in mine])) for k in mine[0] if k not in ("navigator", "path")}
        print(f"{name:13s} bumps {sum(r['bumps'] for r in mine):3d} ({sum(r['bumps'] > 0 for r in mine)} runs)  "
              f"stuck max {max(r['stuck_s'] for r in mine):6.1f} s  area {med['area_m2']:5.1f} m2  "
              f"seen {100 * med['seen']:5.1f} %  revisited {100 * med['revisited']:5.1f} %  "
              f"min seen {100 * min(r['seen'] for r in mine):5.1f} %  min revisited "
              f"{100 * min(r['revisited'] for r in mine):5.1f} %  "
              f"ATE {med['ekf_ate_m']:.3f} / {med['isam2_ate_m']:.3f} m  map {med['ekf_map_m']:.3f} / "
              f"{med['isam2_map_m']:.3f} m  iSAM2 step p99 max {max(r['isam2_p99_ms'] for r in mine):.2f} ms")


def _figure(rows: list[dict], seed: int, png: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from slamio.clutter import clutter_world

    world = clutter_world(seed)
    mine = [r for r in rows if r["seed"] == seed]
    fig, axes = plt.subplots(1, len(mine), figsize=(4 * len(mine), 4.2), squeeze=False)
    for ax, row in zip(axes[0], mine):
        for x0, y0, x1, y1 in world.obstacles.segments_m:
            ax.plot([x0, x1], [y0, y1], color="0.3", lw=1.5)
        for x, y, r in world.obstacles.circles_m:
            ax.add_patch(plt.Circle((x, y), r, color="0.4"))
        ax.scatter([t.x_m for t in world.tags], [t.y_m for t in world.tags], marker="s", s=14, color="tab:orange",
                   label="tags")
        ax.plot(row["path"][:, 0], row["path"][:, 1], lw=0.8, color="tab:blue")
        ax.set_title(f"{row['navigator']}: {row['bumps']} bumps, {100 * row['seen']:.0f} % seen", fontsize=9)
        ax.set_aspect("equal")
        ax.set_xlim(-0.2, world.room_m[0] + 0.2)
        ax.set_ylim(-0.2, world.room_m[1] + 0.2)
        ax.tick_params(labelsize=7)
    fig.suptitle(f"the clutter room of seed {seed}: each navigator's true path", fontsize=10)
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    print(f"wrote {png}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", default=list(NAVIGATORS))
    parser.add_argument("--work", required=True, help="folder for the logs and results (reused)")
    parser.add_argument("--seeds", type=_seeds, default=_seeds("1-10"), help="e.g. 1-10")
    parser.add_argument("--duration", type=float, default=300.0, help="robot seconds per run")
    parser.add_argument("--time-scale", type=float, default=20.0)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--figure", default=None, metavar="PNG", help="the paths of the first seed")
    args = parser.parse_args()
    Path(args.work).mkdir(parents=True, exist_ok=True)
    jobs = [(name, seed) for seed in args.seeds for name in args.names]
    with ThreadPoolExecutor(args.jobs) as pool:  # each run is its own processes
        rows = list(pool.map(lambda job: one_run(*job, args), jobs))
    rows.sort(key=lambda r: (args.names.index(r["navigator"]), r["seed"]))
    _print(rows)
    if args.figure:
        _figure(rows, args.seeds[0], args.figure)


if __name__ == "__main__":
    main()

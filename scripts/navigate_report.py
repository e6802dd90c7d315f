"""Drive every navigator (or those named) through a world for several seeds and print what
each did: bumps, longest stuck, area seen and visited, landmarks seen and revisited, and the
step's CPU time (mean, 99th percentile, largest, of the calling thread: what a step costs
whatever else the machine runs) and its largest wall-clock time. Issue 44's goals: 0 bumps,
never stuck > 10 s, ≥ 90 % of the landmarks seen and ≥ 80 % revisited.

``--world clutter`` (the default): seed N drives in ``clutter_world(N)`` (seeds 1…) from its
start pose, its tags the landmarks, with the depth camera's ±21° scan (the live loop's).
``--world open``: the six-metre test room of ``six_metre_room()``, the 57° ray-cast scan, the
same corner with a different first heading per seed (seeds 0…).

    .venv/bin/python -m scripts.navigate_report [--world clutter] [--seeds 10] [--minutes 5] [--jobs 2] [NAME ...]
"""

from __future__ import annotations

import argparse
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from fgslam.navigate import NAVIGATORS, make_navigator
from fgslam.navigate.harness import drive, six_metre_room
from slamio.clutter import clutter_world


def run(name: str, seed: int, minutes: float, world: str = "clutter") -> dict:
    if world == "clutter":
        result = drive(clutter_world(seed), make_navigator(name, seed=seed), duration_s=60.0 * minutes, seed=seed)
    else:
        obstacles, landmarks = six_metre_room()
        start = (0.8, 0.8, 0.7 + seed)  # the same corner, a different first heading per seed
        result = drive(obstacles, make_navigator(name, seed=seed), start, duration_s=60.0 * minutes,
                       landmarks=landmarks, seed=seed)
    row = result.summary()
    row["step_p50_us"] = float(np.percentile(result.step_cpu_us, 50))
    row["step_p99_us"] = float(np.percentile(result.step_cpu_us, 99))
    row["name"], row["seed"] = name, seed
    return row


def _line(row: dict) -> str:
    return (f"{row['name']:13s} {row['seed']:4d} {row['bumps']:5d} {row['longest_stuck_s']:7.1f} "
            f"{row['area_seen_m2']:7.2f} {row['area_visited_m2']:8.2f} {row['landmarks_seen']:4d}/{row['landmarks']:<2d} "
            f"{row['landmarks_revisited']:6d} {row['step_cpu_mean_us']:10.0f} {row['step_p99_us']:10.0f} "
            f"{row['step_cpu_max_us']:10.0f} {row['step_max_us']:11.0f}")


def _summary(name: str, rows: list[dict]) -> str:
    total = sum(r["landmarks"] for r in rows)
    return (f"{name:13s}  all bumps {sum(r['bumps'] for r in rows)}, runs with a bump "
            f"{sum(r['bumps'] > 0 for r in rows)}/{len(rows)}, longest stuck {max(r['longest_stuck_s'] for r in rows):.1f} s, "
            f"seen {sum(r['landmarks_seen'] for r in rows) / total:.0%} (worst run "
            f"{min(r['landmarks_seen'] / r['landmarks'] for r in rows):.0%}), "
            f"revisited {sum(r['landmarks_revisited'] for r in rows) / total:.0%} (worst run "
            f"{min(r['landmarks_revisited'] / r['landmarks'] for r in rows):.0%}), "
            f"area seen {np.mean([r['area_seen_m2'] for r in rows]):.1f} m², "
            f"visited {np.mean([r['area_visited_m2'] for r in rows]):.1f} m², "
            f"step CPU mean {np.mean([r['step_cpu_mean_us'] for r in rows]):.0f} µs, "
            f"p99 {max(r['step_p99_us'] for r in rows):.0f} µs, max {max(r['step_cpu_max_us'] for r in rows):.0f} µs "
            f"(wall max {max(r['step_max_us'] for r in rows):.0f} µs)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", default=list(NAVIGATORS))
    parser.add_argument("--world", choices=("clutter", "open"), default="clutter")
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--minutes", type=float, default=5.0)
    parser.add_argument("--jobs", type=int, default=1, help="runs in parallel (processes)")
    args = parser.parse_args()
    unknown = [n for n in args.names if n not in NAVIGATORS]
    if unknown:
        parser.error(f"no navigator called {', '.join(unknown)}; choose from {', '.join(NAVIGATORS)}")
    first = 1 if args.world == "clutter" else 0
    print(f"{'navigator':13s} {'seed':>4s} {'bumps':>5s} {'stuck_s':>7s} {'seen_m2':>7s} {'visit_m2':>8s} "
          f"{'lm_seen':>7s} {'lm_rev':>6s} {'cpu_mean_us':>10s} {'cpu_p99_us':>10s} {'cpu_max_us':>10s} {'wall_max_us':>11s}")
    jobs = [(name, seed, args.minutes, args.world) for name in args.names for seed in range(first, first + args.seeds)]
    with ProcessPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        rows = list(pool.map(run, *zip(*jobs))) if args.jobs > 1 else [run(*job) for job in jobs]
    for name in args.names:
        mine = [r for r in rows if r["name"] == name]
        for row in mine:
            print(_line(row))
        print(_summary(name, mine), flush=True)


if __name__ == "__main__":
    main()

"""Drive every navigator (or those named) round the six-metre test room for several seeds and
print what each did: bumps, longest stuck, area seen and visited, landmarks seen and
revisited, and the step's CPU time (median, 99th percentile, largest, of the calling thread:
what a step costs whatever else the machine runs) and its largest wall-clock time. Issue 44's goals: 0 bumps, never stuck > 10 s, ≥ 90 % of the
landmarks seen and ≥ 80 % revisited.

    .venv/bin/python -m scripts.navigate_report [--seeds 10] [--minutes 5] [NAME ...]
"""

from __future__ import annotations

import argparse

import numpy as np

from fgslam.navigate import NAVIGATORS, make_navigator
from fgslam.navigate.harness import drive, six_metre_room


def run(name: str, seed: int, minutes: float) -> dict:
    obstacles, landmarks = six_metre_room()
    start = (0.8, 0.8, 0.7 + seed)  # the same corner, a different first heading per seed
    result = drive(obstacles, make_navigator(name, seed=seed), start, duration_s=60.0 * minutes,
                   landmarks=landmarks, seed=seed)
    row = result.summary()
    row["step_p50_us"] = float(np.percentile(result.step_cpu_us, 50))
    row["step_p99_us"] = float(np.percentile(result.step_cpu_us, 99))
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", default=list(NAVIGATORS))
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--minutes", type=float, default=5.0)
    args = parser.parse_args()
    print(f"{'navigator':13s} {'seed':>4s} {'bumps':>5s} {'stuck_s':>7s} {'seen_m2':>7s} {'visit_m2':>8s} "
          f"{'lm_seen':>7s} {'lm_rev':>6s} {'cpu_p50_us':>10s} {'cpu_p99_us':>10s} {'cpu_max_us':>10s} {'wall_max_us':>11s}")
    for name in args.names:
        rows = []
        for seed in range(args.seeds):
            row = run(name, seed, args.minutes)
            rows.append(row)
            print(f"{name:13s} {seed:4d} {row['bumps']:5d} {row['longest_stuck_s']:7.1f} {row['area_seen_m2']:7.2f} "
                  f"{row['area_visited_m2']:8.2f} {row['landmarks_seen']:4d}/{row['landmarks']:<2d} "
                  f"{row['landmarks_revisited']:6d} {row['step_p50_us']:10.0f} {row['step_p99_us']:10.0f} "
                  f"{row['step_cpu_max_us']:10.0f} {row['step_max_us']:11.0f}", flush=True)
        total = len(rows) * rows[0]["landmarks"]
        print(f"{name:13s}  all bumps {sum(r['bumps'] for r in rows)}, runs with a bump "
              f"{sum(r['bumps'] > 0 for r in rows)}/{len(rows)}, longest stuck {max(r['longest_stuck_s'] for r in rows):.1f} s, "
              f"seen {sum(r['landmarks_seen'] for r in rows) / total:.0%}, "
              f"revisited {sum(r['landmarks_revisited'] for r in rows) / total:.0%}, "
              f"area seen {np.mean([r['area_seen_m2'] for r in rows]):.1f} m², "
              f"visited {np.mean([r['area_visited_m2'] for r in rows]):.1f} m², "
              f"step CPU mean {np.mean([r['step_cpu_mean_us'] for r in rows]):.0f} µs, "
              f"p99 {max(r['step_p99_us'] for r in rows):.0f} µs, max {max(r['step_cpu_max_us'] for r in rows):.0f} µs "
              f"(wall max {max(r['step_max_us'] for r in rows):.0f} µs)", flush=True)


if __name__ == "__main__":
    main()

"""The consistency numbers of one run's mean NEES (docs/estimators.md), the simulated live
camera (docs/camera.md) and the replayed live-simulation laps (README.md)."""

from __future__ import annotations

from doc_numbers.quotes import Quote, row

R, E, C = "README.md", "docs/estimators.md", "docs/camera.md"


def laps(key: str, which):
    """``which`` (min or max) of one score over the ten laps."""
    return lambda m: which(s[key] for s in m)


def lap_means(name: str, which):
    return lambda m: which(s["means"][name] for s in m)


def mean_of_lap_means(name: str):
    return lambda m: sum(s["means"][name] for s in m) / len(m)


Z_RANGES = {0: laps("z_range", min), 1: laps("z_range", max), 2: laps("z_bearing", min), 3: laps("z_bearing", max)}

QUOTES: list[Quote] = [
    *row(E, "each) the run means spread from 0.83 to", "exact-models-nees", "exact models min",
         {0: lambda m: m["means"].min()}),
    *row(E, "7.65 and only 2 of 30 fall inside their independent-pose band [2.74, 3.27]; the mean of the",
         "exact-models-nees", "exact models inside",
         {0: lambda m: m["means"].max(), 1: lambda m: m["inside"], 3: lambda m: m["band"][0],
          4: lambda m: m["band"][1]}),
    *row(E, "30 run means, 2.89, is inside the band of 30 runs [2.19, 3.94]", "exact-models-nees",
         "exact models mean", {1: lambda m: m["means"].mean(), 3: lambda m: m["runs_band"][0],
                               4: lambda m: m["runs_band"][1]}),
    *row(E, "(`tests/data/live-sim/octagon.jsonl`, EKF mean 1.6, band [1.15, 8.0]) stating 0.4 of its σ",
         "live-band", "live band", {0: lambda m: m[1.0].mean_nees, 1: lambda m: m[1.0].low,
                                    2: lambda m: m[1.0].high}),
    *row(E, "comes out at 9.2 against [0.98, 5.81], and at half its σ at 6.05 against [1.04, 5.83]", "live-band",
         "live band overconfident", {0: lambda m: m[0.4].mean_nees, 1: lambda m: m[0.4].low,
                                     2: lambda m: m[0.4].high, 3: lambda m: m[0.5].mean_nees,
                                     4: lambda m: m[0.5].low, 5: lambda m: m[0.5].high}),
    *row(E, "(`tests/test_redraw.py`). Factors nearer 1 (0.7: mean 3.2) stay inside", "live-band",
         "live band 0.7", {2: lambda m: m[0.7].mean_nees}),
    *row(R, "- readings over the σ they state: RMS 0.89–1.05 (range), 1.01–1.21 (bearing);", "live-laps",
         "live laps z", Z_RANGES),
    *row(C, "readings over the σ they state have an RMS of 0.89–1.05 (range) and 1.01–1.21 (bearing).",
         "live-laps", "live laps z camera", Z_RANGES),
    *row(R, "- mean NEES per run 1.08–5.51 (EKF) and 1.36–5.38 (iSAM2); over the ten runs 2.70 and 2.78,",
         "live-laps", "live laps NEES",
         {0: lap_means("ekf", min), 1: lap_means("ekf", max), 2: lap_means("isam2", min),
          3: lap_means("isam2", max), 4: mean_of_lap_means("ekf"), 5: mean_of_lap_means("isam2")}),
]

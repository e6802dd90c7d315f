"""The consistency numbers of one run's mean NEES (docs/results-estimators.md) and of the ten
lockstep laps (docs/results.md, docs/camera.md; reproducible: the same seed drives the same lap);
the live smoother's sliding window on the 40-lap arena (docs/performance.md, without times)."""

from __future__ import annotations

from scripts.doc_numbers.quotes import Quote, row

E = "docs/results-estimators.md"  # "One run's mean NEES", split from docs/estimators.md
P = "docs/performance.md"
R = "docs/results.md"  # moved out of README.md
CAM = "docs/camera.md"


def _lap_values(key: str, estimator: str | None = None):
    """Per-lap values of the live-laps source: a score's ``key``, or its mean NEES for ``estimator``."""
    if estimator is None:
        return lambda m: [score[key] for score in m["scores"]]
    return lambda m: [score["means"][estimator] for score in m["scores"]]


def _lowest(values):
    return lambda m: min(values(m))


def _highest(values):
    return lambda m: max(values(m))


def _mean(values):
    return lambda m: sum(values(m)) / len(values(m))


Z_RANGE, Z_BEARING = _lap_values("z_range"), _lap_values("z_bearing")
EKF_MEANS, ISAM2_MEANS = _lap_values("", "ekf"), _lap_values("", "isam2")


QUOTES: list[Quote] = [
    *row(P, "| its whole run; online ATE × every pose | 8.79 s | 1.86 s; 1.017 | 2.31 s; 1.005 |", "window-arena",
         "window arena online", {2: lambda m: m[200]["online_ratio"], 4: lambda m: m[500]["online_ratio"]}),
    *row(R, "- readings over the σ they state: RMS 0.91–1.08 (range), 0.90–1.14 (bearing);", "live-laps",
         "laps z", {0: _lowest(Z_RANGE), 1: _highest(Z_RANGE), 2: _lowest(Z_BEARING), 3: _highest(Z_BEARING)}),
    *row(CAM, "readings over the σ they state have an RMS of 0.91–1.08 (range) and 0.90–1.14 (bearing).",
         "live-laps", "laps z (camera.md)",
         {0: _lowest(Z_RANGE), 1: _highest(Z_RANGE), 2: _lowest(Z_BEARING), 3: _highest(Z_BEARING)}),
    *row(R, "- mean NEES per run 1.36–4.21 (EKF) and 1.50–4.12 (iSAM2); over the ten runs 2.53 and 2.67,",
         "live-laps", "laps NEES", {0: _lowest(EKF_MEANS), 1: _highest(EKF_MEANS), 2: _lowest(ISAM2_MEANS),
                                    3: _highest(ISAM2_MEANS), 4: _mean(EKF_MEANS), 5: _mean(ISAM2_MEANS)}),
    *row(R, "  inside the band [1.68, 4.70] of ten χ²(3) means;", "live-laps", "laps band of ten",
         {0: lambda m: m["runs_band"][0], 1: lambda m: m["runs_band"][1]}),
    *row(R, "over 100 copies redrawn from the noise the log states (for example seed 10: EKF 2.03 in", "live-laps",
         "laps seed 10", {2: lambda m: m["scores"][9]["bands"]["ekf"].mean_nees}),
    *row(R, "[0.90, 8.01]). A log stating half", "live-laps", "laps seed 10 band",
         {0: lambda m: m["scores"][9]["bands"]["ekf"].low, 1: lambda m: m["scores"][9]["bands"]["ekf"].high}),
    *row(R, "were independent ([2.56, 3.47]): they share", "live-laps", "laps independent band",
         {0: lambda m: m["scores"][0]["independent_band"][0], 1: lambda m: m["scores"][0]["independent_band"][1]}),
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
]

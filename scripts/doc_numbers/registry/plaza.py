"""The Plaza numbers of docs/results.md (once in README.md), docs/results-datasets.md and
docs/datasets.md: the radios' errors against GPS and both estimators under the other run's fitted range model (``scripts/plaza_range_model.py``);
and the replay of the shipped live-simulation log."""

from __future__ import annotations

from scripts.doc_numbers.quotes import Quote, row

R = "docs/results.md"  # moved out of README.md
D = "docs/results-datasets.md"  # the measured sections, split from docs/datasets.md
D_USER = "docs/datasets.md"
S = "plaza"


def result(run: str, kind: str, estimator: str, key: str, scale: float = 1.0):
    """``results[(run, kind)][estimator][key] × scale``."""
    return lambda m: m["results"][(run, kind)][estimator][key] * scale


def model(run: str, key: str):
    return lambda m: getattr(m["models"][run], key)


def report(run: str, *path):
    def read(m):
        value = m["reports"][run]
        for p in path:
            value = value[p]
        return value
    return read


def own_scale(run: str, which):
    return lambda m: which(v["own_scale"] for v in m["reports"][run]["per_landmark"].values())


def by_distance(run: str, index: int, key: str):
    return lambda m: m["reports"][run]["by_distance"][index][key]


def correlation(run: str, index: int):
    return lambda m: m["reports"][run]["reading_correlation"]["correlation"][index]


QUOTES: list[Quote] = []


def _table(run: str, kind: str, first_label: str, label: str, rows: dict[str, str]) -> None:
    """docs/datasets.md's rows for one run and import: estimator → the row's text after the
    label. The first row of each block writes the label in full, the others a short one."""
    name = "Plaza1" if run == "plaza1" else "Plaza2"
    for i, (estimator, cells) in enumerate(rows.items()):
        text = f"| {name} | {first_label if i == 0 else label} | {estimator} | {cells} |"
        offset = 1 if "1.5" in (first_label if i == 0 else label) else 0  # the σ in the label is a number too
        readers = {offset: result(run, kind, estimator, "ate_rmse_m"),
                   offset + 1: result(run, kind, estimator, "ate_aligned_m"),
                   offset + 2: result(run, kind, estimator, "rotation_deg")}
        if estimator != "batch":
            readers[offset + 3] = result(run, kind, estimator, "nis_mean")
            readers[offset + 4] = result(run, kind, estimator, "nis_inside_95", 100.0)
        QUOTES.extend(row(D, text, S, f"{name} {kind} {estimator}", readers))


#: The estimators of docs/datasets.md's table, in the order of its rows.
TABLE_ESTIMATORS = ("ekf", "isam2-fast", "batch")
#: docs/datasets.md's table: (run, import, first row's label, the others') → the rows after them,
#: one an estimator of TABLE_ESTIMATORS.
TABLE = {
    ("plaza1", "default", "default (σ 1.5 m)", "default"):
        ("2.66 | 0.83 | −4.1° | 0.29 | 95.5 %", "3.50 | 1.10 | −5.0° | 0.32 | 95.2 %", "3.51 | 1.10 | −5.0° | – | –"),
    ("plaza1", "fitted", "Plaza2's model", "Plaza2's model"):
        ("0.36 | 0.30 | 0.5° | 0.96 | 94.5 %", "0.24 | 0.21 | 0.2° | 0.96 | 94.8 %", "0.24 | 0.21 | 0.2° | – | –"),
    ("plaza2", "default", "default (σ 1.5 m)", "default"):
        ("4.07 | 2.10 | −6.7° | 1.07 | 97.5 %", "1.79 | 0.78 | −2.4° | 1.45 | 96.4 %", "1.79 | 0.78 | −2.4° | – | –"),
    ("plaza2", "fitted", "Plaza1's model", "Plaza1's model"):
        ("0.76 | 0.46 | 1.2° | 1.32 | 92.5 %", "0.34 | 0.24 | 0.4° | 1.57 | 89.5 %", "0.34 | 0.24 | 0.4° | – | –"),
}
for (run_, kind_, first_, label_), rows_ in TABLE.items():
    _table(run_, kind_, first_, label_, dict(zip(TABLE_ESTIMATORS, rows_, strict=True)))

QUOTES += [
    # the radios' errors (docs/datasets.md)
    *row(D, "| readings | 3 529 | 1 816 |", S, "readings",
         {0: report("plaza1", "observations"), 1: report("plaza2", "observations")}),
    *row(D, "| a constant offset: median, robust spread | 2.84 m, 1.22 m | 2.80 m, 1.77 m |", S, "offset",
         {0: report("plaza1", "constant_offset_fit", "median_offset_m"),
          1: report("plaza1", "constant_offset_fit", "robust_spread_m"),
          2: report("plaza2", "constant_offset_fit", "median_offset_m"),
          3: report("plaza2", "constant_offset_fit", "robust_spread_m")}),
    *row(D, "| median offset at 0–10 m / 45–90 m | 0.59 m / 3.74 m | 0.47 m / 4.38 m |", S, "offset by distance",
         {4: by_distance("plaza1", 0, "median_offset_m"), 5: by_distance("plaza1", -1, "median_offset_m"),
          6: by_distance("plaza2", 0, "median_offset_m"), 7: by_distance("plaza2", -1, "median_offset_m")}),
    *row(D, "| fit `measured = scale · distance + bias` | 1.0694 · d + 0.03 m | 1.0696 · d + 0.01 m |", S, "fit",
         {0: model("plaza1", "range_scale"), 1: model("plaza1", "range_bias_m"),
          2: model("plaza2", "range_scale"), 3: model("plaza2", "range_bias_m")}),
    *row(D, "| each beacon's own scale | 1.0679 – 1.0713 | 1.0687 – 1.0697 |", S, "own scales",
         {0: own_scale("plaza1", min), 1: own_scale("plaza1", max), 2: own_scale("plaza2", min),
          3: own_scale("plaza2", max)}),
    *row(D, "| σ about that line | 0.540 m | 0.555 m |", S, "sigma",
         {0: model("plaza1", "range_sigma_m"), 1: model("plaza2", "range_sigma_m")}),
    *row(D, "| σ at 0–10 m / 45–90 m | 0.59 m / 0.54 m | 0.55 m / 0.57 m |", S, "sigma by distance",
         {4: by_distance("plaza1", 0, "residual_std_m"), 5: by_distance("plaza1", -1, "residual_std_m"),
          6: by_distance("plaza2", 0, "residual_std_m"), 7: by_distance("plaza2", -1, "residual_std_m")}),
    *row(D, "| largest residual | 3.5 σ | 3.5 σ |", S, "largest residual",
         {0: report("plaza1", "largest_residual_sigmas"), 1: report("plaza2", "largest_residual_sigmas")}),
    *row(D, "| outliers (beyond 5 σ) | 0 | 0 |", S, "outliers",
         {1: report("plaza1", "outliers"), 2: report("plaza2", "outliers")}),
    *row(D, "| −0.01 / 0.01 / 0.00 | 0.01 / 0.01 / 0.01 |", S, "correlation",
         {0: correlation("plaza1", 0), 1: correlation("plaza1", 3), 2: correlation("plaza1", 6),
          3: correlation("plaza2", 0), 4: correlation("plaza2", 3), 5: correlation("plaza2", 5)}),
    *row(D_USER, "by +3.15° (Plaza1) and +10.05° (Plaza2)", S, "start heading turn",
         {0: lambda m: m["turn_deg"]["plaza1"], 1: lambda m: m["turn_deg"]["plaza2"]}),
    *row(D, "band less often than 95 %, with the fitted model: EKF 91.9 % (Plaza1) and 86.6 % (Plaza2),\n"
         "  `isam2` 80.1 % and 82.0 %", S, "position NEES",
         {1: result("plaza1", "fitted", "ekf", "nees_inside_95", 100.0),
          2: result("plaza2", "fitted", "ekf", "nees_inside_95", 100.0),
          3: result("plaza1", "fitted", "isam2", "nees_inside_95", 100.0),
          4: result("plaza2", "fitted", "isam2", "nees_inside_95", 100.0)}),
    *row(D, "only 17–51 % are", S, "position NEES, default import",
         {0: lambda m: min(100 * m["results"][(r, "default")][n]["nees_inside_95"]
                           for r in ("plaza1", "plaza2") for n in ("ekf", "isam2")),
          1: lambda m: max(100 * m["results"][(r, "default")][n]["nees_inside_95"]
                           for r in ("plaza1", "plaza2") for n in ("ekf", "isam2"))}),
    *row(D, "Dead reckoning is 1.87 m (Plaza1) and 28.3 m (Plaza2)", S, "dead reckoning",
         {0: result("plaza1", "fitted", "dead_reckoning", "ate_rmse_m"),
          1: result("plaza2", "fitted", "dead_reckoning", "ate_rmse_m")}),
    *row(D, "of the surveyed beacons (EKF 0.34 m and 0.78 m)", S, "EKF map",
         {0: result("plaza1", "fitted", "ekf", "map_rmse_m"), 1: result("plaza2", "fitted", "ekf", "map_rmse_m")}),
    *row(D, "EKF on both runs, aligned or not, and its map is within 0.17 m (Plaza1) and 0.34 m (Plaza2)", S, "MAP map",
         {0: result("plaza1", "fitted", "batch", "map_rmse_m"), 1: result("plaza2", "fitted", "batch", "map_rmse_m")}),
    # README
    *row(R, "`measured = 1.0694 · distance + 0.03 m`", S, "README fit Plaza1",
         {0: model("plaza1", "range_scale"), 1: model("plaza1", "range_bias_m")}),
    *row(R, "`1.0696 · distance + 0.01 m` on Plaza2", S, "README fit Plaza2",
         {0: model("plaza2", "range_scale"), 1: model("plaza2", "range_bias_m")}),
    *row(R, "| Plaza1 | 13 184 | 3 529 | 0.36 | 0.24 | 1.87 | 94.5 % / 94.8 % | 2.66 / 3.51 |", S, "README Plaza1",
         {2: result("plaza1", "fitted", "ekf", "ate_rmse_m"), 3: result("plaza1", "fitted", "batch", "ate_rmse_m"),
          4: result("plaza1", "fitted", "dead_reckoning", "ate_rmse_m"),
          5: result("plaza1", "fitted", "ekf", "nis_inside_95", 100.0),
          6: result("plaza1", "fitted", "isam2-fast", "nis_inside_95", 100.0),
          7: result("plaza1", "default", "ekf", "ate_rmse_m"), 8: result("plaza1", "default", "batch", "ate_rmse_m")}),
    *row(R, "| Plaza2 | 5 907 | 1 816 | 0.76 | 0.34 | 28.3 | 92.5 % / 89.5 % | 4.07 / 1.79 |", S, "README Plaza2",
         {2: result("plaza2", "fitted", "ekf", "ate_rmse_m"), 3: result("plaza2", "fitted", "batch", "ate_rmse_m"),
          4: result("plaza2", "fitted", "dead_reckoning", "ate_rmse_m"),
          5: result("plaza2", "fitted", "ekf", "nis_inside_95", 100.0),
          6: result("plaza2", "fitted", "isam2-fast", "nis_inside_95", 100.0),
          7: result("plaza2", "default", "ekf", "ate_rmse_m"), 8: result("plaza2", "default", "batch", "ate_rmse_m")}),
    *row(R, "(after a rigid alignment as well: 0.21 vs 0.30 m, 0.24 vs 0.46 m)", S, "README aligned",
         {0: result("plaza1", "fitted", "batch", "ate_aligned_m"), 1: result("plaza1", "fitted", "ekf", "ate_aligned_m"),
          2: result("plaza2", "fitted", "batch", "ate_aligned_m"), 3: result("plaza2", "fitted", "ekf", "ate_aligned_m")}),
    *row(R, "within 0.17 m and 0.34 m of the surveyed ones", S, "README MAP map",
         {0: result("plaza1", "fitted", "batch", "map_rmse_m"), 1: result("plaza2", "fitted", "batch", "map_rmse_m")}),
    *row(D, "(an update whenever the data ask for one) at 91.3 %", S, "default isam2 NIS",
         {0: result("plaza2", "fitted", "isam2", "nis_inside_95", 100.0)}),
    *row(R, "89.5 % inside the band, the default `isam2` 91.3 %)", S, "README isam2-fast NIS",
         {0: result("plaza2", "fitted", "isam2-fast", "nis_inside_95", 100.0),
          1: result("plaza2", "fitted", "isam2", "nis_inside_95", 100.0)}),
]

QUOTES += row(R, "Now both estimators' NEES on that log average 1.6, at most 7.6.", "live-replay", "live replay NEES",
              {0: lambda m: m["ekf"]["nees_mean"], 1: lambda m: m["isam2"]["nees_max"]}) + row(
    R, "Now both estimators' NEES on that log average 1.6, at most 7.6.", "live-replay", "live replay NEES isam2",
    {0: lambda m: m["isam2"]["nees_mean"], 1: lambda m: m["ekf"]["nees_max"]})

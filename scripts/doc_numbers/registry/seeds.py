"""docs/seeds.md's numbers: each seed's experiment (flaw costs, the trial calibration, the
height shapes, the stereo drives, the square-vs-octagon paths)."""

from __future__ import annotations

from scripts.doc_numbers.quotes import Quote, parse_number, row
from scripts.doc_numbers.readers import association_rate, flaw, median

S = "docs/seeds.md"
LOGS = ("arena_octagon", "arena_square", "cylinders")

#: Where seed 000's linear bearing and seed 002's gHeight sit among the numbers of a row of the
#: rendered accuracy table: distance, tags found/frames, range, bearing, yaw, cylinders
#: found/frames, range, bearing, height (n), seed 000, seed 002 (none when "—").
SEED000, GHEIGHT = 12, 13


def flaw_row(text: str, setting: str) -> list[Quote]:
    """A row "setting | octagon | square | cylinders" of ATEs from scripts/flaw_costs.py."""
    return row(S, text, "flaw-costs", setting, {i: flaw(log, setting) for i, log in enumerate(LOGS)})


def calibrated(log: str):
    """ekf-s001's ATE on ``log`` (``+cal``: with the trial calibration)."""
    return lambda result: result[log]["ate_rmse_m"]


def calibrated_nees(extreme):
    return lambda result: extreme(100 * result[f"{log}+cal"]["nees_inside_95"] for log in LOGS[:2])


#: The numbers of the trial-calibration sentence, shared with docs/estimators.md.
CALIBRATION_CELLS = {0: calibrated("arena_octagon"), 1: calibrated("arena_octagon+cal"),
                     2: calibrated("arena_square"), 3: calibrated("arena_square+cal"),
                     4: calibrated_nees(min), 5: calibrated_nees(max)}


def gheight_range(extreme):
    """The smallest or largest gHeight error of the accuracy table (1–4 m: 0.5 m has none)."""
    return lambda r: extreme(parse_number(v[GHEIGHT]) for v in r.values() if len(v) > GHEIGHT)


SEED000_001 = [
    *flaw_row("| `ekf` (textbook EKF-SLAM) | 0.011 | 0.011 | 0.026 |", "ekf (textbook EKF-SLAM)"),
    *flaw_row("| dead reckoning | 0.067 | 0.080 | 0.054 |", "dead reckoning"),
    *flaw_row("| `ekf-s000` as written | 2.473 | 2.478 | 2.444 |", "ekf-s000 as written"),
    *flaw_row("| `ekf-s000`, both geometry fixes | 0.101 | 0.117 | 0.171 |", "ekf-s000 with both geometry fixes"),
    *flaw_row("| `ekf-s000`, geometry fixed + the log's noise | 0.049 | 0.058 | 0.058 |",
              "ekf-s000 geometry fixed, log noise instead of unit variances"),
    *row(S, "seed\n000's linear column-to-angle map adds up to 2.95° of bearing error", "camera-accuracy",
         "seed 000 linear bearing, max", {1: lambda r: max(parse_number(v[SEED000]) for v in r.values())}),
    *row(S, "the bundled logs' ATE goes from 0.0337 to 0.0295 m (octagon) and from 0.0162 to\n"
         "   0.0107 m (square), while the NEES inside its band falls to 3–11 %", "trial-calibration",
         "ekf-s001 trial calibration", CALIBRATION_CELLS),
    *row(S, "it associates 83.39 %", "grid200-hidden", "ekf-s001 association, grid 200",
         {0: association_rate("ekf-s001")}),
    *row(S, "the front-end's gHeight option reads\n11.4–12.9 % low at 1–4 m", "camera-accuracy", "gHeight error range",
         {0: gheight_range(min), 1: gheight_range(max)}),
]


def shape_heights(shape: str, method: str):
    """Numbers 1-5 of a row of seeds.md's shape table: the heights in cm at 1.0 → 3.0 m, 0°."""
    return {i + 1: (lambda r, d=d: 100 * r[(shape, d, 0.0)][method]) for i, d in enumerate((1.0, 1.5, 2.0, 2.5, 3.0))}


def summary(method: str, key: str):
    return lambda r: r[method][key]


SEED002 = [
    *row(S, "| circle (24.0 cm) | 21.34, 21.51, 21.39, 21.33, 20.75 cm", "seed002-shapes", "circle gHeight",
         shape_heights("circle", "gheight")),
    *row(S, "| triangle (24.3 cm) | 21.19, 21.03, 20.74, 20.92, — cm", "seed002-shapes", "triangle gHeight",
         {k: v for k, v in shape_heights("triangle", "gheight").items() if k < 5}),
    *row(S, "| rectangle (40.5 cm) | 35.92, 36.02, 35.94, 36.08, 35.56 cm", "seed002-shapes", "rectangle gHeight",
         shape_heights("rectangle", "gheight")),
    *row(S, "(−10.4 … −13.5 %) | 24.02, 24.00, 23.85, 24.24, 23.68 cm", "seed002-shapes", "circle pinhole",
         {k + 1: v for k, v in shape_heights("circle", "pinhole").items()}),
    *row(S, "(−12.8 … −14.6 %) | 23.85, 23.73, 23.49, 23.78, 23.13 cm", "seed002-shapes", "triangle pinhole",
         {k + 1: v for k, v in shape_heights("triangle", "pinhole").items()}),
    *row(S, "(−10.9 … −12.2 %) | 40.49, 40.53, 40.48, 40.71, 40.21 cm", "seed002-shapes", "rectangle pinhole",
         {k + 1: v for k, v in shape_heights("rectangle", "pinhole").items()}),
    *row(S, "Over all 30 frames (both bearings): gHeight −14.6 … −8.6 %, mean −11.5 % (29 of 30 measured",
         "seed002-shapes", "gHeight summary",
         {1: summary("gheight", "min"), 2: summary("gheight", "max"), 3: summary("gheight", "mean"),
          4: summary("gheight", "measured")}),
    *row(S, "the pinhole height\n−4.8 … +3.1 %, mean −0.2 %", "seed002-shapes", "pinhole summary",
         {0: summary("pinhole", "min"), 1: summary("pinhole", "max"), 2: summary("pinhole", "mean")}),
]

SEED003_COLUMNS = ("ekf-s003 as written", "ekf-s003 figures' reading (= IMU dead reckoning)", "ekf-vio",
                   "isam2-vio (online)")


def drive(name: str) -> dict:
    """The four ATEs of a real drive's row (its numbers 2–5: after "0020" and "3-D")."""
    return {i + 2: (lambda r, e=e: r[name][e]) for i, e in enumerate(SEED003_COLUMNS)}


def seed003_mean(estimator: str):
    return lambda result: sum(d[estimator] for d in result.values()) / len(result)


SEED003 = [
    *row(S, "| 0020 ATE 3-D m | 173.2 | 17.2 | 20.1 | 2.0 |", "seed003-real", "seed 003 drive 0020", drive("0020")),
    *row(S, "| 0027 ATE 3-D m | 123.3 | 10.8 | 7.6 | 2.6 |", "seed003-real", "seed 003 drive 0027", drive("0027")),
    *row(S, "| 0042 ATE 3-D m | 609.3 | 18.6 | 7.2 | 4.3 |", "seed003-real", "seed 003 drive 0042", drive("0042")),
    *row(S, "| simulated, seeds 1–10, ATE 3-D m | 96.91 | 0.92 | 0.54 | 0.28 |", "seed003-sim", "seed 003 simulated",
         {i + 3: seed003_mean(e) for i, e in enumerate(SEED003_COLUMNS)}),
]


def paths(tag_noise: str, estimator: str, scale: float):
    """A row of seeds.md's seed-004 table: wins and medians of map error and ATE over seeds 1–20."""
    def pair(r, i):
        return r[("arena-square", i[0])][estimator][i[1]], r[("arena-octagon", i[0])][estimator][i[1]]

    def wins(item):
        return lambda r: sum(pair(r, (s, item))[1] < pair(r, (s, item))[0] for s in range(1, 21))

    def middle(path, item):
        return lambda r: scale * median(r[(path, s)][estimator][item] for s in range(1, 21))

    return {0: wins(0), 1: lambda r: 20, 2: middle("arena-square", 0), 3: middle("arena-octagon", 0),
            4: wins(1), 5: lambda r: 20, 6: middle("arena-square", 1), 7: middle("arena-octagon", 1)}


def views(path: str, key: str):
    return lambda r: median(r[(path, s)][key] for s in range(1, 21))


SEED004 = [
    *[q for text, noise, estimator, scale in (
        ("| measured | `ekf-s004` as written | 12/20 | 2.398 / 2.829 m | 11/20 | 1.971 / 2.565 m |", "measured",
         "ekf-s004", 1),
        ("| measured | `ekf` | 7/20 | 3.6 / 5.7 mm | 3/20 | 5.2 / 7.5 mm |", "measured", "ekf", 1000),
        ("| measured | `isam2` | 5/20 | 3.7 / 5.6 mm | 6/20 | 4.1 / 5.4 mm |", "measured", "isam2", 1000),
        ("| nominal (default) | `ekf-s004` as written | 14/20 | 1.965 / 1.746 m | 15/20 | 3.279 / 2.292 m |",
         "nominal", "ekf-s004", 1),
        ("| nominal (default) | `ekf` | 4/20 | 11.3 / 15.8 mm | 5/20 | 11.2 / 15.2 mm |", "nominal", "ekf", 1000),
        ("| nominal (default) | `isam2` | 4/20 | 10.9 / 15.6 mm | 7/20 | 10.1 / 13.3 mm |", "nominal", "isam2", 1000),
    ) for q in row(S, text, f"seed004-{noise}", f"seed 004 {noise} {estimator}", paths(noise, estimator, scale))],
    *row(S, "| square | 1 160 | 11.4° | 28.8° |", "seed004-measured", "square viewing angles",
         {0: views("arena-square", "sightings"), 1: views("arena-square", "view_spread_deg"),
          2: views("arena-square", "view_span_deg")}),
    *row(S, "| octagon | 784 | 1.9° | 5.7° |", "seed004-measured", "octagon viewing angles",
         {0: views("arena-octagon", "sightings"), 1: views("arena-octagon", "view_spread_deg"),
          2: views("arena-octagon", "view_span_deg")}),
]


SEED001_ROWS = (  # scripts/seed001_association.py: spacing, then "as written / NN only" per noise scale
    "| 0.25 m | 14.2 % / 20.6 % | 21.8 % / 24.5 % | 23.8 % / 25.4 % | 22.0 % / 16.9 % |",
    "| 0.50 m | 61.8 % / 43.5 % | 61.1 % / 53.7 % | 65.1 % / 57.4 % | 31.6 % / 22.0 % |",
    "| 0.75 m | 100.0 % / 100.0 % | 99.9 % / 100.0 % | 91.7 % / 94.8 % | 28.4 % / 36.7 % |",
    "| 1.00 m | 100.0 % / 100.0 % | 100.0 % / 100.0 % | 81.4 % / 83.6 % | 27.6 % / 36.7 % |",
    "| 1.50 m | 100.0 % / 100.0 % | 100.0 % / 100.0 % | 66.9 % / 78.6 % | 22.7 % / 24.3 % |",
    "| 2.00 m | 100.0 % / 100.0 % | 99.5 % / 100.0 % | 60.6 % / 73.5 % | 22.4 % / 27.3 % |",
    "| 3.00 m | 100.0 % / 100.0 % | 99.4 % / 100.0 % | 44.3 % / 68.6 % | 22.3 % / 22.0 % |",
)


def seed001_row(text: str) -> list[Quote]:
    spacing = parse_number(text.split("|")[1].split()[0])
    cells = {}
    for k, scale in enumerate((0.5, 1.0, 2.0, 4.0)):
        for j, variant in enumerate(("as written", "NN only")):
            cells[1 + 2 * k + j] = (lambda r, key=(spacing, scale), v=variant: r[key][v][0])
    return row(S, text, "seed001-association", f"seed 001 association {spacing} m", cells)


SEED001_SPACINGS = (0.25, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0)
GATE_M = 0.5  # ekf-s001's nearest-neighbour gate


def seed001_range(extreme, scale: float, item: int, variants=("as written", "NN only"), spacings=lambda sp: True):
    """The smallest or largest correct % (item 0) or ATE (item 1) over the cells of one noise
    scale, the named variants and the spacings chosen."""
    return lambda r: extreme(r[(sp, scale)][v][item] for sp in SEED001_SPACINGS if spacings(sp) for v in variants)


def below_gate(sp):
    return sp <= GATE_M


def above_gate(sp):
    return sp > GATE_M


SEED001 = [
    *[q for text in SEED001_ROWS for q in seed001_row(text)],
    *row(S, "The as-written ATE at noise ×1 is 0.05–0.27 m, at ×2\n   0.09–1.29 m, at ×4 0.26–4.08 m; NN only "
         "0.03–0.12 m where the spacing exceeds the gate (0.38–0.76 m below it), 0.06–0.51 and 0.40–3.36 m",
         "seed001-association", "seed 001 ATE ranges",
         {1: seed001_range(min, 1.0, 1, ("as written",)), 2: seed001_range(max, 1.0, 1, ("as written",)),
          4: seed001_range(min, 2.0, 1, ("as written",)), 5: seed001_range(max, 2.0, 1, ("as written",)),
          7: seed001_range(min, 4.0, 1, ("as written",)), 8: seed001_range(max, 4.0, 1, ("as written",)),
          9: seed001_range(min, 1.0, 1, ("NN only",), above_gate), 10: seed001_range(max, 1.0, 1, ("NN only",), above_gate),
          11: seed001_range(min, 1.0, 1, ("NN only",), below_gate), 12: seed001_range(max, 1.0, 1, ("NN only",), below_gate),
          13: seed001_range(min, 2.0, 1, ("NN only",)), 14: seed001_range(max, 2.0, 1, ("NN only",)),
          15: seed001_range(min, 4.0, 1, ("NN only",)), 16: seed001_range(max, 4.0, 1, ("NN only",))}),
    *row(S, "(14–62 % correct even at noise ×0.5)", "seed001-association", "below the gate, noise x0.5",
         {0: seed001_range(min, 0.5, 0, spacings=below_gate), 1: seed001_range(max, 0.5, 0, spacings=below_gate)}),
    *row(S, "(≥ 99 %) while", "seed001-association", "above the gate, noise up to x1",
         {0: lambda r: min(seed001_range(min, s, 0, spacings=above_gate)(r) for s in (0.5, 1.0))}),
    *row(S, "(44–95 % correct); at ×4 most of it is wrong\n     (22–37 % correct)", "seed001-association",
         "above the gate, noise x2 and x4",
         {0: seed001_range(min, 2.0, 0, spacings=above_gate), 1: seed001_range(max, 2.0, 0, spacings=above_gate),
          3: seed001_range(min, 4.0, 0, spacings=above_gate), 4: seed001_range(max, 4.0, 0, spacings=above_gate)}),
]

QUOTES: list[Quote] = [*SEED001, *SEED000_001, *SEED002, *SEED003, *SEED004]

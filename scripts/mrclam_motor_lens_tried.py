"""MRCLAM: two physical models tried and not adopted — motor dynamics and lens distortion.

docs/datasets-mrclam-rosbag.md ("Consistency and accuracy: what was tried") quotes this
script's output. Both models are fitted on four robots and scored on the fifth, against
Vicon, straight from the dataset's files (no noise model, no estimator):

1. ``motor``: the importer turns the commanded turn rate into motion with a pure delay and
   a scale (``lag_s`` 0.26 s, ``turn_scale``). A Create's wheels cannot jump to a new speed,
   so a first-order lag (time constant τ) after a shorter delay is the physical alternative:
   it would execute a short turn pulse only in part and a sustained turn in full. Printed:
   the pooled RMS of the heading error over 1 s windows for a grid of (delay, τ) with the
   scale fitted to each, then per robot (leave-one-out scale) the RMS over 1, 4 and 16 s
   windows and the heading error at the first sighting — what rotates the anchored map.
2. ``lens``: the bearing model is linear (``bearing_scale``, ``bearing_bias_rad``). A lens's
   radial distortion would add a term in b³. Printed per robot: the robust σ of the bearing
   error (the run's own median removed, readings within 0.05 rad) with the linear model and
   with the cubic one, both fitted on the other four robots, and the cubic coefficient each
   robot's own readings give.

Usage::

    .venv/bin/python -m scripts.mrclam_motor_lens_tried ../shared/data/mrclam/MRCLAM_Dataset6 [motor|lens ...]

Takes a few seconds.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass

import numpy as np  # noqa: E402
from scipy.signal import lfilter  # noqa: E402

from scripts.common import parse_folder_and_parts, write_json  # noqa: E402
from slamio.datasets.mrclam import MAX_ZERO_BLIP_S, ROBOT_SUBJECTS, fill_zero_blips  # noqa: E402

GRID_S = 0.005  #: integration step of the commanded turn rate
CAMERA_LATENCY_S = 0.03  #: a picture is this much older than its stamp (the fitted model's figure)


@dataclass
class Robot:
    grid_s: np.ndarray  # integration grid (s), from the first command
    omega_radps: np.ndarray  # commanded turn rate on the grid (zero blips filled)
    vicon: np.ndarray  # (n, 4): t, x, y, unwrapped θ
    readings: np.ndarray  # (m, 4): t, landmark subject, range m, bearing rad (known subjects only)


def load(folder: str, k: int) -> Robot:
    def table(name):
        return np.loadtxt(os.path.join(folder, name), comments="#", ndmin=2)

    od = table(f"Robot{k}_Odometry.dat")
    _, omega, _ = fill_zero_blips(od[:, 0], od[:, 1], od[:, 2], MAX_ZERO_BLIP_S)
    grid = np.arange(od[0, 0], od[-1, 0], GRID_S)
    held = omega[np.searchsorted(od[:, 0], grid, side="right") - 1]
    vicon = table(f"Robot{k}_Groundtruth.dat")
    vicon[:, 3] = np.unwrap(vicon[:, 3])
    subject = {int(code): int(s) for s, code in table("Barcodes.dat")}
    me = table(f"Robot{k}_Measurement.dat")
    me[:, 1] = [subject.get(int(c), -1) for c in me[:, 1]]
    return Robot(grid, held, vicon, me)


def landmarks(folder: str) -> dict[int, np.ndarray]:
    rows = np.loadtxt(os.path.join(folder, "Landmark_Groundtruth.dat"), comments="#", ndmin=2)
    return {int(r[0]): r[1:3] for r in rows}


# ----------------------------------------------------------------------------- motor


def executed_turn_rate(omega_radps: np.ndarray, delay_s: float, tau_s: float) -> np.ndarray:
    """The commanded rate delayed by ``delay_s`` and, for τ > 0, through a first-order lag."""
    n = int(round(delay_s / GRID_S))
    delayed = np.concatenate([np.zeros(n), omega_radps[: len(omega_radps) - n]])
    if tau_s <= 0.0:
        return delayed
    a = GRID_S / tau_s
    return lfilter([a], [1.0, a - 1.0], delayed)


def _turn_between(robot: Robot, rate: np.ndarray, t0: np.ndarray, t1: np.ndarray) -> np.ndarray:
    cumulative = np.concatenate([[0.0], np.cumsum(rate) * GRID_S])
    edges = np.concatenate([robot.grid_s, [robot.grid_s[-1] + GRID_S]])
    return np.interp(t1, edges, cumulative) - np.interp(t0, edges, cumulative)


def heading_windows(robot: Robot, delay_s: float, tau_s: float, window_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(commanded turn, Vicon turn) over consecutive windows with Vicon at both ends."""
    t = robot.vicon[:, 0]
    starts = np.arange(t[0] + 5.0, t[-1] - window_s - 5.0, window_s)
    a = np.searchsorted(t, starts)
    b = np.minimum(np.searchsorted(t, starts + window_s), len(t) - 1)
    ok = (np.abs(t[a] - starts) < 0.05) & (np.abs(t[b] - starts - window_s) < 0.05)
    a, b = a[ok], b[ok]
    rate = executed_turn_rate(robot.omega_radps, delay_s, tau_s)
    return _turn_between(robot, rate, t[a], t[b]), robot.vicon[b, 3] - robot.vicon[a, 3]


def fit_turn_scale(robots: list[Robot], delay_s: float, tau_s: float) -> float:
    pairs = [heading_windows(r, delay_s, tau_s, 1.0) for r in robots]
    commanded = np.concatenate([c for c, _ in pairs])
    vicon = np.concatenate([v for _, v in pairs])
    return float(commanded @ vicon / (commanded @ commanded))


def heading_rms_rad(robot: Robot, delay_s: float, tau_s: float, scale: float, window_s: float) -> float:
    commanded, vicon = heading_windows(robot, delay_s, tau_s, window_s)
    return float(np.sqrt(np.mean((vicon - scale * commanded) ** 2)))


def startup_error_deg(robot: Robot, delay_s: float, tau_s: float, scale: float) -> float:
    """Dead-reckoned minus Vicon heading change from the start to the first reading."""
    t = robot.vicon[:, 0]
    a, b = np.searchsorted(t, [robot.grid_s[0], robot.readings[0, 0]])
    rate = scale * executed_turn_rate(robot.omega_radps, delay_s, tau_s)
    turn = _turn_between(robot, rate, t[a : a + 1], t[b : b + 1])[0]
    return float(np.degrees(turn - (robot.vicon[b, 3] - robot.vicon[a, 3])))


def motor_report(robots: dict[int, Robot]) -> dict:
    print("## motor: pooled RMS of the 1 s heading error (rad) by delay and first-order τ, scale fitted")
    grid = []
    for delay in (0.0, 0.1, 0.15, 0.2, 0.26, 0.3):
        for tau in (0.0, 0.05, 0.1, 0.2, 0.3, 0.4):
            scale = fit_turn_scale(list(robots.values()), delay, tau)
            rms = np.sqrt(np.mean([heading_rms_rad(r, delay, tau, scale, 1.0) ** 2 for r in robots.values()]))
            grid.append({"rms_rad": float(rms), "delay_s": delay, "tau_s": tau, "scale": scale})
    grid.sort(key=lambda g: g["rms_rad"])
    result = {"best": grid[0], "pure": next(g for g in grid if g["delay_s"] == 0.26 and g["tau_s"] == 0.0), "robots": {}}
    for g in (result["best"], result["pure"]):
        print(f"delay {g['delay_s']:.2f} s, tau {g['tau_s']:.2f} s: scale {g['scale']:.3f}, RMS {g['rms_rad']:.4f}")
    print("## per robot, scale fitted on the others: RMS at 1 / 4 / 16 s (rad); heading error at the first sighting (deg)")
    for name in ("pure", "best"):
        delay, tau = result[name]["delay_s"], result[name]["tau_s"]
        for k, robot in robots.items():
            scale = fit_turn_scale([r for j, r in robots.items() if j != k], delay, tau)
            cell = {f"rms_{w:g}s": heading_rms_rad(robot, delay, tau, scale, w) for w in (1.0, 4.0, 16.0)}
            cell["startup_deg"] = startup_error_deg(robot, delay, tau, scale)
            result["robots"].setdefault(k, {})[name] = cell
            print(f"{name}, robot {k}: {cell['rms_1s']:.4f} / {cell['rms_4s']:.4f} / {cell['rms_16s']:.4f}; "
                  f"first sighting {cell['startup_deg']:+.2f}")
    return result


# ----------------------------------------------------------------------------- lens


def true_bearings(robot: Robot, surveyed: dict[int, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(Vicon bearing, measured bearing) of every reading of a surveyed landmark."""
    t = robot.vicon[:, 0]
    out = []
    for stamp, subject, _, measured in robot.readings:
        if int(subject) not in surveyed:
            continue
        when = stamp - CAMERA_LATENCY_S
        i = int(np.searchsorted(t, when))
        if i == 0 or i >= len(t) or t[i] - t[i - 1] > 0.1:
            continue
        a = (when - t[i - 1]) / (t[i] - t[i - 1])
        x, y, theta = (1 - a) * robot.vicon[i - 1, 1:] + a * robot.vicon[i, 1:]
        dx, dy = surveyed[int(subject)] - (x, y)
        out.append((np.angle(np.exp(1j * (np.arctan2(dy, dx) - theta))), measured))
    b = np.array(out)
    keep = np.abs(b[:, 1] - b[:, 0]) < 0.05
    return b[keep, 0], b[keep, 1]


def _design(true_b: np.ndarray, cubic: bool) -> np.ndarray:
    cols = [true_b, np.ones_like(true_b)] + ([true_b**3] if cubic else [])
    return np.column_stack(cols)


def fit_bearing(pairs: list[tuple[np.ndarray, np.ndarray]], cubic: bool) -> np.ndarray:
    A = np.vstack([_design(b, cubic) for b, _ in pairs])
    y = np.concatenate([m for _, m in pairs])
    return np.linalg.lstsq(A, y, rcond=None)[0]


def bearing_sigma_rad(pair: tuple[np.ndarray, np.ndarray], coef: np.ndarray) -> float:
    b, measured = pair
    e = measured - _design(b, len(coef) == 3) @ coef
    return float(1.4826 * np.median(np.abs(e - np.median(e))))


def lens_report(robots: dict[int, Robot], surveyed: dict[int, np.ndarray]) -> dict:
    print("## lens: robust sigma of the bearing error (rad), models fitted on the other robots; cubic coefficient")
    pairs = {k: true_bearings(r, surveyed) for k, r in robots.items()}
    result = {}
    for k, pair in pairs.items():
        others = [p for j, p in pairs.items() if j != k]
        linear, cubic, own = fit_bearing(others, False), fit_bearing(others, True), fit_bearing([pair], True)
        result[k] = {"linear_rad": bearing_sigma_rad(pair, linear), "cubic_rad": bearing_sigma_rad(pair, cubic),
                     "k3_others": float(cubic[2]), "k3_own": float(own[2])}
        print(f"robot {k}: linear {result[k]['linear_rad']:.4f}, cubic {result[k]['cubic_rad']:.4f} "
              f"(k3 {cubic[2]:+.3f} from the others, {own[2]:+.3f} from its own readings)")
    return result


def main(argv=None) -> int:
    parser, args, parts = parse_folder_and_parts(__doc__, argv, ("motor", "lens"), "both", "choose motor and/or lens")
    folder = args.folder
    robots = {k: load(folder, k) for k in ROBOT_SUBJECTS if os.path.exists(os.path.join(folder, f"Robot{k}_Odometry.dat"))}
    if not robots:
        parser.error(f"{folder}: no RobotN_Odometry.dat here; give an MRCLAM dataset folder")
    result = {}
    if "motor" in parts:
        result["motor"] = motor_report(robots)
    if "lens" in parts:
        result["lens"] = lens_report(robots, landmarks(folder))
    write_json(args.json, result)
    return 0


if __name__ == "__main__":
    sys.exit(main())

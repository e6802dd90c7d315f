"""The command line starts light: building the parser of every verb and validating a log
import none of the heavy libraries (OpenCV, SciPy, GTSAM, matplotlib, tqdm, the navigators),
whose import is most of a short verb's time (issue 43: ``fgslam validate`` start-up), and
``fgslam validate`` imports neither numpy nor any other verb's module. Checked by the modules
a child process holds, not by a clock. The names the parser keeps to stay light are checked
against the modules they stand for."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
HEAVY = ("slamio.sim", "cv2", "scipy", "gtsam", "matplotlib", "tqdm", "fgslam.navigate", "fgslam.smoother", "ekf",
         "importlib.metadata")

_CHILD = """
import contextlib, io, json, sys
from fgslam.cli import main
with contextlib.redirect_stdout(io.StringIO()):
    try:
        status = main(sys.argv[1:])
    except SystemExit as end:  # --help
        status = end.code
print(json.dumps({"status": status, "modules": sorted(sys.modules)}))
"""


def _modules_after(*argv: str) -> tuple[int, list[str]]:
    done = subprocess.run([sys.executable, "-c", _CHILD, *argv], capture_output=True, text=True, check=True,
                          cwd=ROOT)
    result = json.loads(done.stdout.strip().splitlines()[-1])
    return result["status"], result["modules"]


def _heavy(modules: list[str], heavy: tuple[str, ...] = HEAVY) -> list[str]:
    return [m for m in modules if any(m == h or m.startswith(h + ".") for h in heavy)]


def test_validate_imports_no_heavy_library():
    status, modules = _modules_after("validate", str(ROOT / "data" / "arena_octagon.jsonl"))
    assert status == 0
    assert _heavy(modules) == []


#: What ``fgslam validate`` on a planar log does without: numpy (the reader checks every
#: field without it), the other verbs' modules and the estimator registry.
NOT_FOR_VALIDATE = ("numpy", "fgslam.registry", "fgslam.cli.estimators", "slamio.se3", "slamio.geometry",
                    *(f"fgslam.cli.{m}" for m in ("run", "sim", "bench", "check", "detect", "export", "import_",
                                                   "record", "calibrate", "calibrate_camera", "tune_colours", "live")))


def test_validate_imports_neither_numpy_nor_the_other_verbs(tmp_path):
    mounted = tmp_path / "mounted.jsonl"  # a sensor off the robot's centre, and readings beyond its range
    header, *records = (ROOT / "data" / "arena_square.jsonl").read_text().splitlines()
    header_fields = json.loads(header)
    header_fields["sensor"].update(pose_on_robot=[0.1, 0.0, 0.05], max_range_m=1.0)
    mounted.write_text("\n".join([json.dumps(header_fields), *records]) + "\n")
    for log in (ROOT / "data" / "arena_octagon.jsonl", ROOT / "data" / "arena_square.jsonl", mounted):
        status, modules = _modules_after("validate", str(log))
        assert status == 0
        assert _heavy(modules, NOT_FOR_VALIDATE) == [], log.name


def test_validate_of_a_3d_log_imports_no_numpy(tmp_path):
    """A 3-D log's header (its stereo calibration, a rigid cam_T_imu) is checked without numpy too."""
    drive = tmp_path / "drive.jsonl"
    subprocess.run([sys.executable, "-m", "fgslam.cli", "sim", "stereo-loop", "--seed", "1", "--out", str(drive)],
                   check=True, capture_output=True, cwd=ROOT)
    status, modules = _modules_after("validate", str(drive))
    assert status == 0
    assert _heavy(modules, NOT_FOR_VALIDATE) == []


def test_help_lists_every_verb_without_importing_one():
    from fgslam.cli.verbs import VERBS

    status, modules = _modules_after("--help")
    assert status == 0
    assert _heavy(modules, ("numpy", *(f"fgslam.cli.{m}" for m, _ in VERBS.values()))) == []
    listed = subprocess.run([sys.executable, "-m", "fgslam.cli", "--help"], capture_output=True, text=True,
                            check=True, cwd=ROOT).stdout
    every_verb_built = subprocess.run(  # the same text as with every verb's own parser built
        [sys.executable, "-c", "from fgslam.cli import build_parser; print(build_parser().format_help(), end='')"],
        capture_output=True, text=True, check=True, cwd=ROOT).stdout
    assert listed == every_verb_built
    for verb, (_, help_line) in VERBS.items():
        assert f"    {verb} " in listed or f"    {verb}\n" in listed
        assert help_line.split()[0] in listed


def test_the_names_the_parser_keeps_are_the_modules_names():
    from fgslam.cli import live_navigate, sim
    from fgslam.navigate import NAVIGATORS
    from slamio.camera.chessboard import MODELS
    from slamio.camera.model import DISTORTION_MODELS
    from slamio.sim import SCENARIOS
    from slamio.sim3d import STEREO_LOOP

    assert live_navigate.NAVIGATORS == tuple(NAVIGATORS)
    assert sim.SCENARIOS == tuple(SCENARIOS) and sim.STEREO_LOOP == STEREO_LOOP
    assert MODELS == DISTORTION_MODELS


def test_version_is_read_when_asked(capsys):
    from importlib.metadata import version

    from fgslam.cli import main

    try:
        main(["--version"])
    except SystemExit as end:
        assert end.code == 0
    assert capsys.readouterr().out.strip() == f"fgslam {version('fgslam')}"

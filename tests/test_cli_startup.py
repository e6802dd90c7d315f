"""The command line starts light: building the parser of every verb and validating a log
import none of the heavy libraries (OpenCV, SciPy, GTSAM, matplotlib, tqdm, the navigators),
whose import is most of a short verb's time (issue 43: ``fgslam validate`` start-up). Checked
by the modules a child process holds, not by a clock. The names the parser keeps to stay
light are checked against the modules they stand for."""

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
    status = main(sys.argv[1:])
print(json.dumps({"status": status, "modules": sorted(sys.modules)}))
"""


def _modules_after(*argv: str) -> tuple[int, list[str]]:
    done = subprocess.run([sys.executable, "-c", _CHILD, *argv], capture_output=True, text=True, check=True,
                          cwd=ROOT)
    result = json.loads(done.stdout.strip().splitlines()[-1])
    return result["status"], result["modules"]


def test_validate_imports_no_heavy_library():
    status, modules = _modules_after("validate", str(ROOT / "data" / "arena_octagon.jsonl"))
    assert status == 0
    heavy = [m for m in modules if any(m == h or m.startswith(h + ".") for h in HEAVY)]
    assert heavy == []


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

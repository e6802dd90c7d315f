"""Every script in scripts/ answers ``--help`` with its usage and does no work.

The docs quote these scripts' commands; a user's first step is ``--help``. A script that
took ``--help`` as a log path, or ignored it and ran a minute-long measurement, is what this
guards against. Each runs in its own interpreter, as a user runs it (about a second each:
GTSAM and numpy load), so the test is marked slow (CI runs it; ``make test`` leaves it out).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

SCRIPTS = sorted((Path(__file__).resolve().parents[1] / "scripts").glob("*.py"))


@pytest.mark.slow
@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: p.name)
def test_script_answers_help(script: Path) -> None:
    done = subprocess.run([sys.executable, str(script), "--help"], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.startswith("usage:"), done.stdout[:500]


def test_there_are_scripts() -> None:
    assert len(SCRIPTS) > 20

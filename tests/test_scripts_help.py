"""Every script of the ``scripts`` package answers ``--help`` with its usage and does no work.

The docs quote these scripts' commands (``python -m scripts.NAME ...`` from the repository's
root); a user's first step is ``--help``. A script that took ``--help`` as a log path, or
ignored it and ran a minute-long measurement, is what this guards against. Each runs in its
own interpreter, as a user runs it (about a second each: GTSAM and numpy load), so the test is
marked slow (CI runs it; ``make test`` leaves it out). The package itself holds no
import-path edits: ``python -m`` from the root is what makes ``scripts`` importable.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "scripts"
#: The runnable scripts, as module names under ``scripts``: every module of the package and of
#: its ``experiments`` folder but the packages' own and the shared one.
SCRIPTS = sorted(".".join(p.relative_to(PACKAGE).with_suffix("").parts)
                 for folder in (PACKAGE, PACKAGE / "experiments") for p in folder.glob("*.py")
                 if p.stem not in ("__init__", "common"))


@pytest.mark.slow
@pytest.mark.parametrize("name", SCRIPTS)
def test_script_answers_help(name: str) -> None:
    done = subprocess.run([sys.executable, "-m", f"scripts.{name}", "--help"], cwd=ROOT, capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.startswith("usage:"), done.stdout[:500]


def test_there_are_scripts() -> None:
    assert len(SCRIPTS) > 20


@pytest.mark.parametrize("path", sorted(PACKAGE.rglob("*.py")), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_no_script_edits_the_import_path_or_reaches_into_a_private_name(path: Path) -> None:
    """No import-path edits (the package is imported as ``scripts``), and no ``from scripts.x
    import _name``: what several scripts share is public, in :mod:`scripts.common`."""
    text = path.read_text(encoding="utf-8")
    assert not re.search(r"sys\.path\.(insert|append)|sys\.path\s*\+?=", text), "edits the import path"
    assert not re.search(r"^\s*from scripts(\.\w+)* import \(?\s*_\w", text, re.M), "imports a private name"

"""The CLI verbs live in one package, one module per verb, with no import cycle, one error
path and one progress facility (issue 15)."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

import pytest

import fgslam.cli as cli

PACKAGE = Path(cli.__file__).parent
VERB_MODULES = {"sim": "sim", "run": "run", "import": "import_", "export": "export", "validate": "validate",
                "check": "check", "bench": "bench", "record": "record", "calibrate": "calibrate",
                "detect": "detect", "tune-colours": "tune_colours", "calibrate-camera": "calibrate_camera",
                "live": "live"}


def test_one_module_per_verb_each_with_its_parser_and_handler():
    assert {m.__name__.rsplit(".", 1)[1] for m in cli.VERBS} == set(VERB_MODULES.values())
    parser = cli.build_parser()
    verbs = next(a for a in parser._actions if a.dest == "verb").choices
    assert set(verbs) == set(VERB_MODULES)
    for verb, module_name in VERB_MODULES.items():
        module = getattr(cli, module_name)
        assert callable(module.add_parser)
        handler = getattr(module, f"cmd_{verb.replace('-', '_')}")
        assert verbs[verb].get_default("func") is handler


@pytest.mark.parametrize("path", sorted(PACKAGE.glob("*.py")), ids=lambda p: p.name)
def test_no_module_of_the_package_imports_the_package_itself(path):
    """Verb modules take what they share from fgslam.cli.common / .progress, never from
    fgslam.cli (its __init__ imports them): no import cycle."""
    if path.name in ("__init__.py", "__main__.py"):
        return
    tree = ast.parse(path.read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module == "fgslam.cli":
            pytest.fail(f"{path.name}:{node.lineno} imports from fgslam.cli itself")
        if isinstance(node, ast.Import) and any(alias.name == "fgslam.cli" for alias in node.names):
            pytest.fail(f"{path.name}:{node.lineno} imports fgslam.cli itself")


def test_each_verb_module_imports_on_its_own():
    code = "; ".join(f"import fgslam.cli.{m}" for m in ["common", "progress", *VERB_MODULES.values()])
    subprocess.run([sys.executable, "-c", code], check=True)


def test_one_progress_facility_and_one_error_path():
    source = {p.name: p.read_text() for p in PACKAGE.glob("*.py")}
    assert not hasattr(cli, "ProgressBar")
    for name, text in source.items():
        if name != "progress.py":
            assert "\\r" not in text and "isatty" not in text, f"{name} draws progress itself"
        if name != "common.py":
            assert not re.search(r"print\(f?[\"'](fgslam|\{PROG\}): error", text), f"{name} prints errors itself"
    assert not (PACKAGE.parent / "live_cli.py").exists() and not (PACKAGE.parent / "cli.py").exists()


def test_the_old_module_names_still_work():
    from fgslam.detect_cli import DetectError, add_detect_parser, merge_observations  # noqa: F401
    from fgslam.record_cli import add_calibrate_parser, add_record_parser, main

    assert main is cli.main and add_record_parser is cli.record.add_parser
    assert add_calibrate_parser is cli.calibrate.add_parser


def test_python_m_fgslam_cli_is_fgslam():
    out = subprocess.run([sys.executable, "-m", "fgslam.cli", "--help"], capture_output=True, text=True, check=True)
    assert "usage: fgslam" in out.stdout and "record" in out.stdout

"""The ``fgslam`` command line: one module per verb, one error path, one progress display.

- ``fgslam.cli.<verb>`` (``sim``, ``run``, ``import_``, ``export``, ``validate``, ``check``,
  ``bench``, ``record``, ``calibrate``, ``detect``, ``tune_colours`` (``tune-colours``), ``live``): ``add_parser(verbs)`` adds the
  verb and its ``--help``; ``cmd_<verb>(args)`` does it and returns the exit status. :func:`main`
  imports the module of the verb it runs and no other (a short verb such as ``validate``
  starts in the time of its own imports); ``fgslam --help`` lists every verb from
  :mod:`fgslam.cli.verbs` (each verb's name, module and help line) without importing one.
- :mod:`fgslam.cli.common`: the one error path (:func:`~fgslam.cli.common.run_verb`: every
  :class:`~slamio.errors.FgslamError` or :class:`OSError` becomes ``fgslam: error: <what,
  where, how to fix it>`` and exit status 1 — status 2 when an input file cannot be used,
  :class:`~slamio.errors.InputFileError`, see :func:`main`; ``fgslam run`` returns 4 when an
  estimator failed mid-run, :data:`fgslam.failure.FAILED_EXIT_STATUS`), reading logs, and outputs that
  never replace what the user has unless asked (``--overwrite``).
- :mod:`fgslam.cli.progress`: the one progress display (tqdm).

Verb modules import from ``common`` and ``progress`` only, never from this package's
``__init__``: no import cycle.
"""

from __future__ import annotations

import argparse
import functools
import importlib
import re
import sys
from types import ModuleType
from typing import Collection, Sequence

from fgslam.cli.common import fail, run_verb
from fgslam.cli.verbs import VERBS as VERB_TABLE
from slamio.errors import InputFileError

__all__ = ["main", "build_parser", "ESTIMATOR_HELP", "VERBS"]

DESCRIPTION = """\
fgslam compares factor-graph smoothing (GTSAM iSAM2) against EKF-SLAM on the same
run log: a 2-D landmark log (range/bearing observations, planar odometry) or a 3-D
stereo camera + IMU log (seed 003). The log says its dimension; run, check and bench
pick the estimators that take it. Record, import or simulate a run, run every
estimator on it, read the comparison.

typical use:
  fgslam sim arena-octagon --seed 1 --out run.jsonl
  fgslam run run.jsonl --out results/
  fgslam sim stereo-loop --seed 1 --out drive.jsonl     (a 3-D log)
  fgslam run drive.jsonl --out results3d/
"""


def __getattr__(name: str):
    """The verb modules (``fgslam.cli.run``, ...), :data:`VERBS` and :data:`ESTIMATOR_HELP`,
    imported when first asked for: ``fgslam VERB`` imports that verb's module alone."""
    if name in _MODULES:
        return importlib.import_module(f"{__name__}.{name}")
    if name == "VERBS":  # the verb modules, in the order ``fgslam --help`` lists them
        return tuple(_module(verb) for verb in VERB_TABLE)
    if name == "ESTIMATOR_HELP":
        from fgslam.cli.estimators import ESTIMATOR_HELP

        return ESTIMATOR_HELP
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


_MODULES = frozenset(module for module, _ in VERB_TABLE.values())


def _module(verb: str) -> ModuleType:
    return importlib.import_module(f"{__name__}.{VERB_TABLE[verb][0]}")


class _Parser(argparse.ArgumentParser):
    """argparse with fgslam's one error path: a mistake in the command line is one line,
    ``fgslam: error: ...`` with the verb's ``--help`` to read, and exit status 1 (argparse's
    own is a usage block and status 2)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        # A value that starts with a minus and a digit is a value, never an option (no fgslam
        # option looks like that): `--range-bias -1e9`, `--centre -1.5,2`. argparse (before
        # Python 3.13) takes only plain negative numbers, and read these as an unknown option.
        self._negative_number_matcher = re.compile(r"^-\.?\d")

    def error(self, message: str):  # type: ignore[override]
        self.exit(1, f"fgslam: error: {message} (see {self.prog} --help)\n")


def build_parser(verbs: Collection[str] | None = None) -> argparse.ArgumentParser:
    """``fgslam``'s parser. ``verbs``: the verbs whose own parser (options, handler) is built,
    their modules imported; every other verb is listed with its help line only (enough for
    ``fgslam --help`` and for a wrong verb's message). Default: every verb, built."""
    parser = _Parser(
        prog="fgslam", description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--version", action=_VersionAction, nargs=0, help="show the version and exit")
    subparsers = parser.add_subparsers(dest="verb", metavar="VERB", required=True)
    for verb, (_, help_line) in VERB_TABLE.items():
        if verbs is None or verb in verbs:
            _module(verb).add_parser(subparsers)
        else:
            subparsers.add_parser(verb, help=help_line, add_help=False).set_defaults(func=None)
    return parser


def _verb_named(argv: Sequence[str]) -> str | None:
    """The verb ``argv`` names (its first argument that is no option), if fgslam has it."""
    verb = next((arg for arg in argv if not arg.startswith("-")), None)
    return verb if verb in VERB_TABLE else None


class _VersionAction(argparse.Action):
    """``--version``, reading the installed version only when asked: importlib.metadata costs
    ~30 ms of every start-up otherwise."""

    def __call__(self, parser, namespace, values, option_string=None):
        print(f"fgslam {_version()}")  # on stdout, as argparse's own version action
        parser.exit(0)


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("fgslam")
    except PackageNotFoundError:
        return "unknown"


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    verb = _verb_named(argv)
    parser = build_parser(() if verb is None else (verb,))
    args, extra = parser.parse_known_args(argv)
    if getattr(args, "func", True) is None:  # a verb other than the one guessed: build them all
        parser = build_parser()
        args, extra = parser.parse_known_args(argv)
    if extra:  # `import DATASET SOURCE --robot 2 OUT`: positionals after an option
        if getattr(args, "takes_extra_paths", False) and not any(e.startswith("-") for e in extra):
            args.paths.extend(extra)
        else:
            parser.error(f"unrecognized arguments: {' '.join(extra)}")
    args.argv = argv
    return run_verb(_input_file_status(args.func), args)


def _input_file_status(func):
    """``func`` (a verb), exiting with :attr:`InputFileError.exit_status` (2) when an input
    file cannot be used — missing, not a regular file, too large, or holding what its reader
    refuses — after the same one line as every user error; a mistake in the command (an
    option, an output) stays status 1."""

    @functools.wraps(func)
    def verb(args: argparse.Namespace) -> int:
        try:
            return func(args)
        except InputFileError as error:
            fail(error)
            return error.exit_status
        except RuntimeError as error:  # Python < 3.13: Path.resolve() says ELOOP as RuntimeError
            if not str(error).startswith("Symlink loop from "):
                raise
            looped = str(error)[len("Symlink loop from "):].strip("'\"")
            fail(InputFileError(f"{looped}: a loop of symbolic links (a link that leads, through others, back "
                                "to itself); point the link at the real file"))
            return InputFileError.exit_status

    return verb


if __name__ == "__main__":
    sys.exit(main())

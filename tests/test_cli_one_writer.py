"""One writer per output, results folders that fgslam alone empties, and a full disk
(issue 40, items 4 and "disk full"):

- a second fgslam writing the same --out is refused, one line naming the holder's pid, and
  writes nothing; once the holder is gone the same command works;
- reusing --out removes only regular files fgslam wrote: never a folder, never a symbolic
  link (nor its target), whatever a hand-edited manifest.json lists;
- a write that fails (here: a file-size limit, EFBIG, as a full disk gives ENOSPC) is one
  line naming the file; the files written whole are kept and listed, nothing half-written
  stays, and the same command run again succeeds without --overwrite.

No sleeps: the lock holder is a child process that says when it holds the lock, and the
full disk is ``RLIMIT_FSIZE`` in a child process (SIGXFSZ ignored, so writes past the
limit fail with EFBIG).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from fgslam.cli import main

SIM = ["sim", "arena-square", "--seed", "1", "--laps", "1"]
QUICK = ["--estimators", "ekf", "--no-consistency"]

HOLD_LOCK = """
import sys
from slamio.filelock import OutputLock
lock = OutputLock(sys.argv[1]).acquire()
print("held", flush=True)
sys.stdin.read()  # until the test closes our stdin
"""

LIMITED = """
import resource, signal, sys
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails with EFBIG instead
limit = int(sys.argv[1])
resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
from fgslam.cli import main
sys.exit(main(sys.argv[2:]))
"""


@pytest.fixture(scope="module")
def log(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("log") / "square.jsonl"
    assert main([*SIM, "--out", str(path)]) == 0
    return path


def error_line(text: str) -> str:
    """The one ``fgslam: error:`` line of ``text`` (stderr), no traceback."""
    lines = [line for line in text.splitlines() if line.startswith("fgslam: error: ")]
    assert len(lines) == 1 and "Traceback" not in text, text
    return lines[0]


class Holder:
    """A child process holding the lock of an output until :meth:`release`."""

    def __init__(self, output: Path):
        self.proc = subprocess.Popen([sys.executable, "-c", HOLD_LOCK, str(output)], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, text=True)
        assert self.proc.stdout.readline() == "held\n"  # it holds the lock now

    def release(self) -> None:
        self.proc.stdin.close()
        self.proc.wait(timeout=60)
        self.proc.stdout.close()


@pytest.fixture
def holder():
    held: list[Holder] = []

    def hold(output: Path) -> Holder:
        held.append(Holder(output))
        return held[-1]

    yield hold
    for h in held:
        if h.proc.poll() is None:
            h.release()


def limited(limit: int, argv: list[str], cwd: Path) -> subprocess.CompletedProcess:
    """``fgslam argv`` in a child process whose files cannot grow past ``limit`` bytes."""
    return subprocess.run([sys.executable, "-c", LIMITED, str(limit), *argv], cwd=cwd, capture_output=True,
                          text=True, timeout=600)


# --------------------------------------------------------------------------- one writer per output


def test_a_second_run_into_the_same_out_is_refused_naming_the_holder(log, tmp_path, capsys, monkeypatch, holder):
    import fgslam.runner

    out = tmp_path / "r"
    held = holder(out)
    with monkeypatch.context() as patch:
        patch.setattr(fgslam.runner, "compare_log", lambda *a, **k: pytest.fail("ran while --out was busy"))
        assert main(["run", str(log), "--out", str(out), *QUICK]) == 1
    line = error_line(capsys.readouterr().err)
    assert f"--out {out} is being written by process {held.proc.pid}" in line and "wait for it" in line
    assert not out.exists()  # nothing written
    held.release()
    assert main(["run", str(log), "--out", str(out), *QUICK, "--no-report"]) == 0
    assert json.loads((out / "manifest.json").read_text())["complete"] is True
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".fgslam-lock")]  # released when done


@pytest.mark.parametrize("argv", [
    ["bench", "arena-square", "--runs", "1", "--out", "{out}"],
    [*SIM, "--out", "{out}", "--overwrite"],
    ["export", "rosbag", "{log}", "{out}"],
    ["calibrate", "data/calibration_trials_s001.csv", "--out", "{out}"],
    ["import", "victoria-park", "{out}"],
], ids=lambda argv: argv[0])
def test_every_writing_verb_refuses_a_busy_output(log, tmp_path, capsys, holder, argv):
    out = tmp_path / "busy"
    held = holder(out)
    argv = [str(out) if a == "{out}" else str(log) if a == "{log}" else a for a in argv]
    assert main(argv) == 1
    assert f"is being written by process {held.proc.pid}" in error_line(capsys.readouterr().err)
    assert not out.exists()


# --------------------------------------------------------------------------- what --out reuse removes


def test_a_hand_edited_manifest_never_removes_a_folder_or_a_link(log, tmp_path, capsys):
    out = tmp_path / "r"
    assert main(["run", str(log), "--out", str(out), *QUICK, "--no-report"]) == 0
    outside = tmp_path / "precious.txt"
    outside.write_text("the user's")
    (out / "data").mkdir()
    (out / "data" / "inside.txt").write_text("the user's too")
    (out / "link.txt").symlink_to(outside)
    manifest = json.loads((out / "manifest.json").read_text())
    manifest["files"] += ["data", "link.txt", "../precious.txt", str(outside), "."]
    (out / "manifest.json").write_text(json.dumps(manifest))
    assert main(["run", str(log), "--out", str(out), *QUICK, "--no-report"]) == 0
    assert (out / "data" / "inside.txt").read_text() == "the user's too"
    assert (out / "link.txt").is_symlink() and outside.read_text() == "the user's"
    assert set(json.loads((out / "manifest.json").read_text())["files"]).isdisjoint({"data", "link.txt"})


@pytest.mark.parametrize("overwrite", [[], ["--overwrite"]], ids=["manifest", "overwrite"])
@pytest.mark.parametrize("kind", ["folder", "link"])
def test_a_folder_or_link_under_an_own_name_is_refused_before_the_run(log, tmp_path, capsys, monkeypatch, kind,
                                                                      overwrite):
    import fgslam.runner

    out = tmp_path / "r"
    assert main(["run", str(log), "--out", str(out), *QUICK, "--no-report"]) == 0
    target = tmp_path / "mine"
    target.mkdir()
    (target / "keep.txt").write_text("keep")
    (out / "ekf.tum").unlink()
    if kind == "folder":
        (out / "ekf.tum").mkdir()
        (out / "ekf.tum" / "keep.txt").write_text("keep")
    else:
        (out / "ekf.tum").symlink_to(target)
    monkeypatch.setattr(fgslam.runner, "compare_log", lambda *a, **k: pytest.fail("ran before the check"))
    assert main(["run", str(log), "--out", str(out), *QUICK, *overwrite]) == 1
    line = error_line(capsys.readouterr().err)
    assert str(out / "ekf.tum") in line and ("a folder" if kind == "folder" else "a symbolic link") in line
    assert "never removes a folder" in line
    assert (out / "ekf.tum" / "keep.txt").read_text() == "keep" and (out / "metrics.json").is_file()


def test_without_a_manifest_overwrite_removes_only_regular_files_of_its_own_names(log, tmp_path):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    (out / "batch.tum").write_text("an old batch.tum")  # one of fgslam's names, a regular file
    (out / "figures").mkdir()
    assert main(["run", str(log), "--out", str(out), *QUICK, "--no-report", "--overwrite"]) == 0
    names = {p.name for p in out.iterdir()}
    assert {"notes.txt", "figures", "ekf.tum"} <= names and "batch.tum" not in names


def test_a_run_killed_while_writing_leaves_a_folder_the_next_run_replaces(log, tmp_path, monkeypatch):
    import fgslam.compare

    out = tmp_path / "r"
    real = fgslam.compare.write_tum

    def killed(path, *args):
        if Path(path).name == "dead_reckoning_online.tum":  # some files are written whole, then it "dies"
            raise KeyboardInterrupt
        real(path, *args)

    with monkeypatch.context() as patch:
        patch.setattr(fgslam.compare, "write_tum", killed)
        assert main(["run", str(log), "--out", str(out), "--estimators", "ekf,dead_reckoning", "--no-consistency",
                     "--no-report"]) == 130
    interim = json.loads((out / "manifest.json").read_text())
    assert interim["complete"] is False and "dead_reckoning.tum" in interim["planned"]
    assert (out / "dead_reckoning.tum").is_file()  # written whole before the end, listed nowhere yet
    (out / ".ekf.tum.4242.0123abcd.tmp").write_text("half a file a killed writer left")
    assert main(["run", str(log), "--out", str(out), *QUICK, "--no-report"]) == 0  # no --overwrite needed
    names = {p.name for p in out.iterdir()}
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["complete"] is True and set(manifest["files"]) == names
    assert "dead_reckoning.tum" not in names and not [n for n in names if n.startswith(".")]


# --------------------------------------------------------------------------- a full disk


def test_run_on_a_full_disk_names_the_file_keeps_the_complete_ones_and_reruns(log, tmp_path):
    out = tmp_path / "r"
    argv = ["run", str(log), "--out", str(out), *QUICK]
    done = limited(20_000, argv, tmp_path)  # metrics.json fits, reference.tum (~38 kB) does not
    assert done.returncode == 1, done.stderr
    line = error_line(done.stderr)
    assert line.startswith(f"fgslam: error: {out / 'reference.tum'}: File too large") and "run the same command" in line
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["complete"] is False and manifest["files"] == ["metrics.json", "manifest.json"]
    assert "reference.tum" in manifest["error"]
    assert sorted(p.name for p in out.iterdir()) == ["manifest.json", "metrics.json"]  # nothing partial
    json.loads((out / "metrics.json").read_text())  # the kept file is whole
    assert main(argv) == 0  # the rerun: no --overwrite, nothing in the way
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["complete"] is True and {"reference.tum", "report.html"} <= set(manifest["files"])
    assert "error" not in manifest


def test_bench_on_a_full_disk_names_the_file_and_reruns(tmp_path):
    out = tmp_path / "b"
    argv = ["bench", "arena-square", "--runs", "2", "--jobs", "1", "--out", str(out)]
    done = limited(4_000, argv, tmp_path)  # montecarlo.json (~40 kB) does not fit
    assert done.returncode == 1, done.stderr
    assert error_line(done.stderr).startswith(f"fgslam: error: {out / 'montecarlo.json'}: File too large")
    assert sorted(p.name for p in out.iterdir()) == ["manifest.json"]
    assert json.loads((out / "manifest.json").read_text())["complete"] is False
    assert main(argv) == 0
    assert {"montecarlo.json", "nees.png", "ate.png"} <= {p.name for p in out.iterdir()}


def test_export_on_a_full_disk_leaves_no_bag_and_reruns(log, tmp_path):
    bag = tmp_path / "bag"
    argv = ["export", "rosbag", str(log), str(bag)]
    done = limited(50_000, argv, tmp_path)  # the bag's database is ~2 MB
    assert done.returncode == 1, done.stderr
    line = error_line(done.stderr)
    assert f"OUT {bag}: writing the bag failed" in line and "run the same command again" in line
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # no half bag, no temporary folder
    assert main(argv) == 0 and (bag / "metadata.yaml").is_file()


def test_sim_on_a_full_disk_names_the_log_and_leaves_nothing(tmp_path):
    out = tmp_path / "run.jsonl"
    done = limited(10_000, [*SIM, "--out", str(out)], tmp_path)
    assert done.returncode == 1, done.stderr
    assert error_line(done.stderr).startswith(f"fgslam: error: {out}: File too large")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full")
def test_a_write_error_names_the_final_file_not_a_temporary_one(tmp_path):
    from fgslam.atomic import write_whole

    target = tmp_path / "metrics.json"

    def to_a_full_disk(tmp):
        with open("/dev/full", "w") as full:
            full.write("x" * 100_000)
            full.flush()

    with pytest.raises(OSError) as raised:
        write_whole(target, to_a_full_disk)
    assert raised.value.filename == str(target) and raised.value.strerror == "No space left on device"
    assert list(tmp_path.iterdir()) == []

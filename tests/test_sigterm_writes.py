"""SIGTERM (a scheduler's stop, `kill`) while a command writes: one line, exit status 143, nothing half written.
The kill helpers are test_crash_safety.py's."""

import signal
from pathlib import Path

import pytest

from ermrl.errors import TERMINATED

from cli_runs import ermrl
from test_crash_safety import TEST, TINY, TRAIN, KillPoint, cli, folder_trigger, run_and_kill


@pytest.fixture(scope="module")
def small_study(tmp_path_factory) -> Path:
    """A folder holding the study 'k' (4 trials) in run/."""
    folder = tmp_path_factory.mktemp("sigterm")
    r = ermrl("evolve", "--env", "CartPoleNoVel-v1", *TINY, "--popsize", "2", "--trials", "4", "--study", "k",
              "--out", "run", "--no-estimate", "--quiet", cwd=folder)
    assert r.returncode == 0, r.stderr
    return folder


def _hidden_trigger(folder: Path):
    """True once an atomic write's hidden temporary file (``.NAME.XXXXXXXX.SUFFIX``) is in ``folder``; the empty
    folder that checks an output path (``.ermrl-check-*``) is not one."""
    return lambda: any(not p.name.startswith(".ermrl-check-") for p in folder.glob(".*"))


@pytest.mark.parametrize("command", ["train", "test", "report"])
def test_sigterm_while_a_command_writes_ends_with_143_and_leaves_nothing_half_written(small_study, tmp_path, command):
    """SIGTERM (a scheduler's stop, `kill`) while `train` or `test` writes its run folder, or `report` its files:
    one line, exit status 143, and no run folder, staging folder or temporary file left (before: the process died
    at once, leaving its hidden staging folder or a hidden 0-byte temporary file beside report.html)."""
    import shutil

    work = tmp_path / "w"
    shutil.copytree(small_study, work)
    if command == "train":
        cmd, folder = cli(*TRAIN), work / "run2"
        cmd[cmd.index("run")] = "run2"
        trigger = folder_trigger(KillPoint("write", 0.0), folder)
    elif command == "test":
        cmd, folder = cli(*TEST), work / "run" / "test"
        trigger = folder_trigger(KillPoint("write", 0.0), folder)
    else:
        cmd, folder = cli("report", "--study", "k", "--out", "run"), work / "run" / "report.html"
        trigger = _hidden_trigger(work / "run")
    stopped, r = run_and_kill(cmd, work, KillPoint("write", 0.0), trigger, signal.SIGTERM)
    assert stopped, r.stderr
    assert r.returncode == TERMINATED and r.stderr.splitlines()[-1] == "terminated (SIGTERM)"
    assert not folder.exists()
    assert [p.name for p in work.rglob(".*")] == []


SIGTERM_IN_ZIP = """
import os, signal, sys
from ermrl.cli import main

def kill_once_a_zip_member_is_open(frame, event, arg):
    # SIGTERM just as ZipFile.open hands back a member's write handle: NumPy's savez then closes the zip in its
    # `finally` over that open handle, and zipfile's ValueError replaces the SystemExit SIGTERM raised
    if event == "return" and frame.f_code.co_name == "_open_to_write" and frame.f_globals["__name__"] == "zipfile":
        sys.setprofile(None)
        os.kill(os.getpid(), signal.SIGTERM)

sys.setprofile(kill_once_a_zip_member_is_open)
sys.exit(main(sys.argv[1:]))
"""


def test_sigterm_whose_unwinding_a_library_replaces_with_its_own_error_still_ends_with_143(small_study, tmp_path):
    """SIGTERM that lands while NumPy's savez holds a zip member open for writing: zipfile's own clean-up error
    ("Can't close the ZIP file while there is an open writing handle") replaces the stop on its way out; the
    command still ends with one line and exit status 143, and leaves no run folder or temporary file (before: exit
    status 1 and "unexpected ValueError ... please report it")."""
    import shutil
    import subprocess
    import sys

    work = tmp_path / "w"
    shutil.copytree(small_study, work)
    r = subprocess.run([sys.executable, "-c", SIGTERM_IN_ZIP, *TEST], cwd=work, capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == TERMINATED, r.stderr
    assert r.stderr.splitlines()[-1] == "terminated (SIGTERM)"
    assert not (work / "run" / "test").exists()
    assert [p.name for p in work.rglob(".*")] == []

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

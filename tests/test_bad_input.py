"""Bad input, as a new user types it, across every command: each case ends with exit code 2 and exactly one line
on stderr that names the problem and the fix, before any work starts (no JAX compile) and without writing
anything (the working folder is byte-for-byte the same afterwards).

The cases run the real CLI in-process (``ermrl.cli.main``), in a copy of a small working folder that holds the
files bad input points at: a plain file, a folder, a malformed curves.csv, damaged config files, an npz that is
no agent, and a SQLite storage with three studies (``empty``: an ermrl study without trials, ``one``: one
completed trial, ``plain``: not made by ermrl). A few cases run as subprocesses: the environment variable read
at import (ERMRL_CPU_DEVICES) and ``--debug``. The matrix of cases is in bad_input_cases.py.
"""

from __future__ import annotations

import os
import re
import shutil
import sqlite3
from pathlib import Path

import numpy as np
import pytest

from bad_input_cases import CASES
from ermrl.evolution.record import decode_study_record, encode_study_record
from ermrl.cli import main

from cli_runs import ermrl_process as ermrl

CORES = os.cpu_count() or 1


def _template(folder: Path) -> None:
    """The files the cases point at (paths relative to the working folder)."""
    import optuna

    from ermrl import storage
    from ermrl.evolution.config import EvolveConfig
    from ermrl.evolution.search_space import SearchSpace
    from ermrl.evolution.study import ATTR
    from ermrl.training import TrainConfig

    folder.mkdir()
    (folder / "afile").write_text("not a folder, not JSON\n")
    (folder / "adir").mkdir()
    (folder / "curves_bad").mkdir()
    (folder / "curves_bad" / "curves.csv").write_text("model,seed\nPPO,0\n")
    configs = {"list.yaml": "- units\n- 20\n", "scalar.yaml": "5\n", "unk.toml": "unitz = 20\n",
               "str.toml": 'units = "ten"\n', "float.toml": "units = 2.5\n", "bad.toml": "units = \n",
               "choice.toml": 'bias = "gaussian"\n', "bool.toml": "skip-connection = 1\n",
               "many.toml": "units = [10, 20]\n", "nested.toml": "[units]\nn = 1\n", "x.json": "{}\n",
               "evolvekey.toml": "trials = 5\n", "timesteps.yaml": "timesteps: 1e5\n"}
    for name, text in configs.items():
        (folder / name).write_text(text)
    (folder / "latin1.toml").write_bytes('units = "é"\n'.encode("latin-1"))
    (folder / "adir.toml").mkdir()
    np.savez(folder / "badagent.npz", weights=np.zeros(3))
    (folder / "junk.log").write_text("a log, not Optuna's\nsecond line\n")
    (folder / "notes.log").write_text("one line of notes, which Optuna would take for a torn record\n")
    (folder / "tiny.db").write_bytes(b"x")  # no SQLite database: SQLite would overwrite it
    other = sqlite3.connect(folder / "other.db")  # another program's database: Optuna would add its tables
    other.execute("CREATE TABLE notes (text)")
    other.commit()
    other.close()
    (folder / "list.json").write_text("[]\n")
    (folder / "mine" / "agents" / "mine").mkdir(parents=True)  # a user's folder: `train --out` must not touch it
    (folder / "mine" / "agents" / "README.md").write_text("my notes\n")
    (folder / "mine" / "agents" / "mine" / "policy.pt").write_bytes(b"weights")
    (folder / "phase" / "agents" / "PPO").mkdir(parents=True)  # a test phase is no train run
    (folder / "phase" / "test_config.json").write_text("{}\n")
    (folder / "phase" / "agents" / "PPO" / "seed1000.npz").write_bytes(b"agent")
    (folder / "notes.snapshot").write_text("a user's file where `train --out notes` would keep its snapshot\n")
    (folder / "test.partial").mkdir()  # where the test phase of a study in this folder keeps its finished models
    (folder / "test.partial" / "notes.txt").write_text("a user's file\n")

    url = f"sqlite:///{folder / 'studies.db'}"
    space = SearchSpace(1, fixed_iss=1.0)
    config = EvolveConfig(train=TrainConfig(env_id="CartPoleNoVel-v1", total_timesteps=2048), space=space,
                          trials=1, seeds=1)
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    for name in ("empty", "one", "plain"):
        study = optuna.create_study(storage=url, study_name=name, direction="maximize")
        if name != "plain":
            study.set_user_attr(ATTR, encode_study_record(config))
        if name == "one":
            study.add_trial(optuna.trial.create_trial(params={"sr": 0.95, "lr": 0.5},
                                                      distributions=space.distributions(), value=20.0))


@pytest.fixture(scope="module")
def template(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("bad-input") / "work"
    _template(folder)
    return folder


def snapshot(folder: Path) -> dict[str, tuple[int, int]]:
    """Every path under ``folder`` with its size and modification time (ns): any write shows."""
    return {str(p.relative_to(folder)): (p.stat().st_size, p.stat().st_mtime_ns) for p in sorted(folder.rglob("*"))}


@pytest.fixture
def compiles():
    """The XLA programs compiled while a test runs (JAX's monitoring events), other than single eager jax.numpy
    or lax operations (making a gymnax env's parameters compiles a few): bad input must fail before training."""
    import jax
    import jax.monitoring
    import jax.numpy as jnp

    events = []

    def listener(event, duration, **kwargs):
        name = kwargs.get("fun_name", "?").removeprefix("jit(").removesuffix(")")
        if event == "/jax/core/compile/backend_compile_duration" and not (hasattr(jax.lax, name) or hasattr(jnp, name)):
            events.append(kwargs.get("fun_name", "?"))

    jax.monitoring.register_event_duration_secs_listener(listener)
    yield events
    jax.monitoring.unregister_event_duration_listener(listener)


@pytest.fixture
def work(template, tmp_path, monkeypatch) -> Path:
    folder = tmp_path / "work"
    shutil.copytree(template, folder)
    monkeypatch.chdir(folder)
    return folder


def run_in_process(argv: list[str], capsys) -> tuple[int, str, str]:
    try:
        code = main(argv)
    except SystemExit as e:  # argparse's --help and --version only
        code = e.code
    captured = capsys.readouterr()
    return code, captured.out, captured.err


@pytest.mark.parametrize("command, message", CASES, ids=[c for c, _ in CASES])
def test_bad_input_is_one_line_exit_2_and_writes_nothing(work, capsys, compiles, command, message):
    import shlex

    before = snapshot(work)
    code, out, err = run_in_process(shlex.split(command), capsys)
    assert (code, re.sub(r"\d[\d,]* GiB", "MEM GiB", err)) == (2, message + "\n")  # MEM: this machine's figures
    assert out == ""
    assert snapshot(work) == before
    assert compiles == []


def test_the_matrix_covers_every_command():
    commands = {c.split()[0] if c else "" for c, _ in CASES}
    assert {"train", "evolve", "select", "test", "report", "plot", "baselines", "experiment", "analyze", "video",
            "dashboard", "compare", "test-progress", "reproduce"} <= commands
    assert len(CASES) >= 50


def _shown(cell: str, full: str) -> bool:
    """Whether a docs table cell shows ``full``: the same text, or (for a long one) its start then "…"."""
    cell = cell.replace("\\|", "|")
    return cell == full or ("…" in cell and full.startswith(cell.split("…")[0]) and len(cell.split("…")[0]) >= 12)


def test_the_reliability_docs_list_every_case_in_order():
    """docs/reliability.md's table "The cases" shows this matrix, row i for case i, with its exact message (a long
    input or message shows its start, then "…"), so the page cannot drift from what the CLI prints."""
    text = (Path(__file__).parents[1] / "docs" / "reliability.md").read_text().split("### The cases", 1)[1]
    rows = [re.split(r"(?<!\\)\|", line)[1:-1] for line in text.split("\n#", 1)[0].splitlines()
            if re.match(r"^\| \d+ \|", line)]
    assert len(rows) >= len(CASES)
    for i, (command, message) in enumerate(CASES):
        number, shown_command, shown_message, code = (cell.strip() for cell in rows[i])
        expected = f"| {i + 1} | `{('ermrl ' + command).strip()}` | {message.replace('|', chr(92) + '|')} | 2 |"
        assert number == str(i + 1) and code == "2", expected
        assert _shown(shown_command.split("`")[1], ("ermrl " + command).strip()), expected
        assert _shown(shown_message, message), expected


def test_a_mujoco_gl_that_mujoco_refuses_is_named(work, capsys, monkeypatch):
    """MUJOCO_GL is read when MuJoCo is imported; a value it refuses is a one-line error before any env is made."""
    monkeypatch.setenv("MUJOCO_GL", "opengl")
    before = snapshot(work)
    code, out, err = run_in_process(["train", "--env", "Hopper-v5"], capsys)
    assert (code, err) == (2, "ermrl train: error: MUJOCO_GL='opengl' is not a renderer MuJoCo knows; set it to egl "
                              "or osmesa (no screen) or glfw, or unset it\n")
    assert snapshot(work) == before
    # a non-MuJoCo env does not care
    code, out, err = run_in_process(["train", "--env", "CartPole-v1", "--units", "0"], capsys)
    assert err.startswith("ermrl train: error: units must be >= 1")


def test_debug_keeps_the_traceback_and_the_exit_code(work, capsys):
    """--debug, after the command or before it: the traceback, then the same line and exit code 2."""
    for argv, line in ((["train", "--units", "0", "--debug"], "ermrl train: error: units must be >= 1, got 0; a "
                                                              "reservoir needs at least one neuron"),
                       (["--debug", "train", "--units", "x"], "ermrl train: error: argument --units: invalid int value: "
                                                              "'x'; see `ermrl train --help`"),
                       (["--debug", "train", "--config", "unk.toml"], "ermrl train: error: config file unk.toml: "
                                                                      "unknown option 'unitz' for `ermrl train`; did "
                                                                      "you mean 'units'?")):
        code, out, err = run_in_process(argv, capsys)
        lines = err.splitlines()
        assert code == 2 and lines[0] == "Traceback (most recent call last):" and lines[-1] == line, err
        assert lines[-2] == "ermrl.errors.ConfigError: " + line.split(": error: ", 1)[1]


def test_as_a_subprocess_with_a_bad_cpu_device_count(work):
    """The real process: ERMRL_CPU_DEVICES is read at import, and refused before any work."""
    before = snapshot(work)
    r = ermrl("evolve", "--popsize", "1", env={"ERMRL_CPU_DEVICES": "abc"}, cwd=work)
    assert (r.returncode, r.stdout, r.stderr) == (2, "", "ermrl evolve: error: ERMRL_CPU_DEVICES must be a whole "
                                                         "number >= 1 (the CPU devices a population is sharded over), "
                                                         f"got 'abc'; unset it to use one per core ({CORES})\n")
    r = ermrl("evolve", "--popsize", "1", cwd=work)
    assert (r.returncode, r.stdout, r.stderr) == (2, "", "ermrl evolve: error: --popsize must be >= 2 (CMA-ES needs at "
                                                         "least 2 candidates a generation), got 1\n")
    assert snapshot(work) == before


def test_help_and_version_still_exit_0(capsys):
    from ermrl import __version__

    assert run_in_process(["--version"], capsys)[:2] == (0, f"ermrl {__version__}\n")
    code, out, _ = run_in_process(["train", "--help"], capsys)
    assert code == 0 and "--debug" in out and "traceback" in out

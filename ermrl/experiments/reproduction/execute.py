"""Runs a reproduction step's actions (:mod:`.actions`) in the repository's root, or writes them out as shell
lines (``ermrl reproduce --dry-run``).

Each command is its own process: ``ermrl`` is this interpreter's (``python -m ermrl.cli``, or the command in
``$ERMRL``), a ``python`` script runs on this interpreter, a ``reference`` one on ``$REF_PYTHON`` (default
``.venv-ref/bin/python``); all of them with the root first on PYTHONPATH, so that they import this checkout's
``ermrl``. A command that fails ends the step and the run (RunFailed, exit 1): rerun it to resume, since every
command resumes where it stopped. An experiment's files are stashed even then. With a time limit (``stop_at``,
``ermrl reproduce --stop-after``), every ``ermrl evolve`` and ``ermrl experiment run`` gets ``--stop-after`` with
the time left, no command starts once it has passed, and a command that stopped for it (exit status 75) ends the
run with :class:`~ermrl.errors.OutOfTime`.
"""

from __future__ import annotations

import datetime
import glob
import os
import shlex
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Callable

from ermrl.errors import OUT_OF_TIME, OutOfTime, RunFailed
from ermrl.experiments.reproduction import folders
from ermrl.experiments.reproduction.actions import (
    Action, Collect, CopyFiles, Experiment, MakeDirs, Remove, Run, Step, StopIf, shell_guard,
)

REFERENCE_PYTHON = ".venv-ref/bin/python"
"""The reference pipeline's interpreter (``make reference``), unless ``$REF_PYTHON`` names another."""


def _program(run: Run) -> list[str]:
    """The words before a command's arguments, as they run."""
    if run.program == "ermrl":
        return shlex.split(os.environ["ERMRL"]) if os.environ.get("ERMRL") else [sys.executable, "-m", "ermrl.cli"]
    if run.program == "python":
        return [sys.executable]
    return [os.environ.get("REF_PYTHON") or REFERENCE_PYTHON]


def _shown_program(run: Run) -> str:
    return {"ermrl": "ermrl", "python": "python"}.get(run.program) or os.environ.get("REF_PYTHON") or REFERENCE_PYTHON


def command_line(run: Run) -> str:
    """``run`` as one shell line: its skip conditions, the command (values known when it runs in ``<...>``), and
    its output's redirection."""
    words = [a if isinstance(a, str) else a.text() for a in run.args]
    line = shell_guard(run.skip_if) + " ".join([_shown_program(run), *map(shlex.quote, words)])
    if run.tee is not None:
        line += f" | tee {'-a ' if run.append else ''}{shlex.quote(run.tee)}"
    elif not run.show:
        line += " >/dev/null"
    return line


def lines(action: Action) -> list[str]:
    """What ``action`` does, as shell lines; the file moves of an experiment as comments."""
    if isinstance(action, Run):
        return [command_line(action)]
    if isinstance(action, Experiment):
        f = action.folder
        return [f"# restore docs/data/{f} -> runs/experiments/{f}", command_line(action.command()),
                f"# collect runs/experiments/{f} -> docs/data/{f}",
                f"# stash runs/experiments/{f} -> docs/data/{f} (also when the run stops)"]
    if isinstance(action, Collect):
        return [f"# collect runs/experiments/{action.folder} -> docs/data/{action.folder}"]
    if isinstance(action, CopyFiles):
        files = " ".join(shlex.quote(f"{action.source}/{n}") for n in action.names)
        return [shell_guard(action.skip_if) + f"{{ mkdir -p {shlex.quote(action.target)} && cp {files} "
                f"{shlex.quote(action.target)}/; }}"]
    if isinstance(action, Remove):
        return ["rm -f " + " ".join(action.patterns)]
    if isinstance(action, MakeDirs):
        return [shell_guard(action.skip_if) + f"mkdir -p {shlex.quote(action.path)}"]
    if isinstance(action, StopIf):
        return [" && ".join(c.shell() for c in action.conditions) + f" && echo {shlex.quote(action.message)}"
                "  # and the step ends there"]
    raise TypeError(f"not a reproduction action: {action!r}")


def header(step: Step) -> str:
    return f"== {step.name} ({' '.join(step.claims) or 'no claim'}): {step.description}"


def dry_run(step: Step, write: Callable[[str], None] = print) -> None:
    """Writes ``step``'s header and actions as shell lines; runs nothing."""
    write(header(step))
    for action in step.actions:
        for line in lines(action):
            write(line)


def run_step(step: Step, root: Path, write: Callable[[str], None] = print, stop_at: float | None = None) -> None:
    """Runs ``step``'s actions in order in ``root``; RunFailed when a command fails, OutOfTime when the time limit
    ``stop_at`` (a ``time.time()``) stopped it."""
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%H:%M:%S")
    write(f"== {step.name} ({now} UTC)")
    for action in step.actions:
        if _act(step, action, root, write, stop_at) is _STOP:
            return


_STOP = object()


def _skipped(conditions, root: Path) -> bool:
    return bool(conditions) and all(c.holds(root) for c in conditions)


def _act(step: Step, action: Action, root: Path, write: Callable[[str], None], stop_at: float | None = None):
    if isinstance(action, Run):
        if not _skipped(action.skip_if, root):
            _run(step, action, root, stop_at)
    elif isinstance(action, Experiment):
        for other in folders.journals_elsewhere(root, action.name, action.scale):
            print(f"warning: {other.relative_to(root)} holds studies of {action.name} at {action.scale}, but this step "
                  f"reads docs/data/{action.folder}/studies.log; move the journal there to continue them",
                  file=sys.stderr)
        folders.restore(root, action.folder)
        try:  # also when the run is stopped (Ctrl-C, a failure)
            _run(step, action.command(), root, stop_at)
            folders.collect(root, action.folder)
        finally:
            folders.stash(root, action.folder)
    elif isinstance(action, Collect):
        folders.collect(root, action.folder)
    elif isinstance(action, CopyFiles):
        if not _skipped(action.skip_if, root):
            (root / action.target).mkdir(parents=True, exist_ok=True)
            for name in action.names:
                shutil.copy(root / action.source / name, root / action.target / name)
    elif isinstance(action, Remove):
        for pattern in action.patterns:
            for path in glob.glob(str(root / pattern)):
                Path(path).unlink(missing_ok=True)
    elif isinstance(action, MakeDirs):
        if not _skipped(action.skip_if, root):
            (root / action.path).mkdir(parents=True, exist_ok=True)
    elif isinstance(action, StopIf):
        if _skipped(action.conditions, root):
            write(action.message)
            return _STOP
    else:
        raise TypeError(f"not a reproduction action: {action!r}")
    return None


TIMED = (("evolve",), ("experiment", "run"))
"""The ``ermrl`` commands that take ``--stop-after``."""


def _run(step: Step, run: Run, root: Path, stop_at: float | None = None) -> None:
    """Runs one command in ``root``, its values resolved now; its output shown (and kept for ``tee``); RunFailed
    when it fails. Ctrl-C reaches the command too, which stops on its own; any other stop (SIGTERM) stops it.
    With ``stop_at``: OutOfTime instead of starting once it has passed, or when the command stopped for it."""
    argv = _program(run) + [w for a in run.args for w in ([a] if isinstance(a, str) else a.resolve(root))]
    if stop_at is not None:
        left = stop_at - time.time()
        if left < 1:
            raise OutOfTime(f"stopped before step {step.name}'s `{command_line(run)}`: the time limit has passed; "
                            "rerun the same command to continue")
        if run.program == "ermrl" and any(tuple(run.args[:len(words)]) == words for words in TIMED):
            argv += ["--stop-after", f"{int(left)}s"]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(root), os.environ.get("PYTHONPATH")])),
           "PYTHONIOENCODING": "utf-8"}
    captured = run.tee is not None or not run.show
    sys.stdout.flush()
    proc = subprocess.Popen(argv, cwd=root, env=env, stdout=subprocess.PIPE if captured else None,
                            text=True, encoding="utf-8")
    kept: list[str] = []
    try:
        if captured:
            for line in proc.stdout:
                kept.append(line)
                if run.show:
                    sys.stdout.write(line)
                    sys.stdout.flush()
        code = proc.wait()
    except KeyboardInterrupt:
        proc.wait()  # it got the same Ctrl-C
        raise
    except BaseException:
        proc.terminate()
        proc.wait()
        raise
    if code == OUT_OF_TIME and stop_at is not None:
        raise OutOfTime(f"step {step.name}: `{command_line(run)}` stopped before the time limit with work left; "
                        "rerun the same command to continue")
    if code != 0:
        raise RunFailed(f"step {step.name}: `{command_line(run)}` exited with status {code}; rerun `ermrl reproduce "
                        f"{step.name}` to resume it")
    if run.tee is not None:
        path = root / run.tee
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(path, "a" if run.append else "w", encoding="utf-8") as f:
            f.write("".join(kept))

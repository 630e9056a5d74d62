"""How the tests run the ``ermrl`` CLI and the benchmark scripts.

``ermrl(*args)`` calls ``ermrl.cli.main(args)`` in the test's own process, with stdout and stderr captured, and
returns what ``subprocess.run`` would: the exit code that the console script would exit with, and the two texts.
It is the same code path as the console script (``sys.exit(main())``) minus the interpreter's start-up, and the
process keeps JAX's compiled programs between runs, so the many tests that train the same small population
compile it once per test worker instead of once per run (an ``ermrl`` process spends ≈ 4 s importing and 10–15 s
compiling such a run; see docs/benchmarks.md). ``script(path, *args)`` runs a script (``benchmarks/*.py``,
``paper/*.py``) as ``python PATH ARGS`` would, in this process too.

``ermrl_process(*args)`` starts a real ``python -m ermrl.cli`` process. The tests that need one use it: signals
and kills, environment variables read at import, pipes and their buffering, several workers at once; and
test_cli.py checks that a run gives the same output and results both ways.
"""

import contextlib
import io
import os
import runpy
import subprocess
import sys
from pathlib import Path

COMMAND = [sys.executable, "-m", "ermrl.cli"]


def _exit_code(e: SystemExit) -> int:
    """The status that the interpreter exits with for ``e`` (a message is printed to stderr: status 1)."""
    if e.code is None or isinstance(e.code, int):
        return e.code or 0
    print(e.code, file=sys.stderr)
    return 1


def _in_process(call, argv: list[str], cwd) -> subprocess.CompletedProcess:
    out, err = io.StringIO(), io.StringIO()
    here, argv0 = os.getcwd(), sys.argv
    try:
        if cwd is not None:
            os.chdir(cwd)
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = call()
            except SystemExit as e:  # argparse's errors, --help and --version; a script's exit
                code = _exit_code(e)
    finally:
        os.chdir(here)
        sys.argv = argv0
    return subprocess.CompletedProcess(argv, code, out.getvalue(), err.getvalue())


def ermrl(*args, cwd=None) -> subprocess.CompletedProcess:
    """``ermrl ARGS`` run in this process from folder ``cwd`` (default: the current one)."""
    from ermrl.cli import main

    argv = [str(a) for a in args]
    return _in_process(lambda: main(argv), ["ermrl", *argv], cwd)


def script(path: Path, *args, cwd=None) -> subprocess.CompletedProcess:
    """``python PATH ARGS`` run in this process: the file executed as ``__main__`` with ``sys.argv`` set."""
    argv = [str(path), *map(str, args)]

    def run():
        sys.argv = argv
        runpy.run_path(str(path), run_name="__main__")
        return 0

    return _in_process(run, argv, cwd)


def ermrl_process(*args, cwd=None, env=None, timeout=900, **kwargs) -> subprocess.CompletedProcess:
    """``python -m ermrl.cli ARGS`` as a subprocess, its output captured as text; ``env`` is added to this
    process's environment."""
    return subprocess.run([*COMMAND, *map(str, args)], capture_output=True, text=True, cwd=cwd, timeout=timeout,
                          env=None if env is None else {**os.environ, **env}, **kwargs)

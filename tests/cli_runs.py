"""How the tests run the ``ermrl`` CLI.

``ermrl(*args)`` calls ``ermrl.cli.main(args)`` in the test's own process, with stdout and stderr captured, and
returns what ``subprocess.run`` would: the exit code that the console script would exit with, and the two texts.
It is the same code path as the console script (``sys.exit(main())``) minus the interpreter's start-up, and the
process keeps JAX's compiled programs between runs, so the many tests that train the same small population
compile it once per test worker instead of once per run (an ``ermrl`` process spends ≈ 4 s importing and 10–15 s
compiling such a run; see docs/benchmarks.md).

``ermrl_process(*args)`` starts a real ``python -m ermrl.cli`` process. The tests that need one use it: signals
and kills, environment variables read at import, pipes and their buffering, several workers at once.
"""

import contextlib
import io
import os
import subprocess
import sys

COMMAND = [sys.executable, "-m", "ermrl.cli"]


def ermrl(*args: str, cwd=None) -> subprocess.CompletedProcess:
    """``ermrl ARGS`` run in this process from folder ``cwd`` (default: the current one)."""
    from ermrl.cli import main

    out, err = io.StringIO(), io.StringIO()
    here = os.getcwd()
    try:
        if cwd is not None:
            os.chdir(cwd)
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main([str(a) for a in args])
            except SystemExit as e:  # argparse's --help and --version
                code = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
    finally:
        os.chdir(here)
    return subprocess.CompletedProcess(["ermrl", *args], code, out.getvalue(), err.getvalue())


def ermrl_process(*args: str, cwd=None, env=None, timeout=900, **kwargs) -> subprocess.CompletedProcess:
    """``python -m ermrl.cli ARGS`` as a subprocess, its output captured as text; ``env`` is added to this
    process's environment."""
    return subprocess.run([*COMMAND, *map(str, args)], capture_output=True, text=True, cwd=cwd, timeout=timeout,
                          env=None if env is None else {**os.environ, **env}, **kwargs)

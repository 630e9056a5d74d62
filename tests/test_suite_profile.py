"""benchmarks/suite_profile.py: a pytest run whose test compiles a function in-process and another in a
subprocess of its own, beside a test that compiles nothing; the summary must count both processes, name both
functions, and put both programs to the test that compiled them."""

import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parent.parent / "benchmarks" / "suite_profile.py"

INNER = '''
import subprocess
import sys

import jax
import jax.numpy as jnp


def doubled(x):
    return 2 * x


def test_compiles_here_and_in_a_subprocess():
    assert float(jax.jit(doubled)(jnp.ones(3)).sum()) == 6.0
    code = "import jax, jax.numpy as jnp\\ndef tripled(x): return 3 * x\\nprint(float(jax.jit(tripled)(jnp.ones(2)).sum()))"
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout == "6.0\\n"


def test_compiles_nothing():
    assert sum(range(4)) == 6
'''


def test_the_profile_counts_every_process_and_names_each_compiled_function(tmp_path):
    (tmp_path / "test_inner.py").write_text(INNER)
    r = subprocess.run([sys.executable, str(SCRIPT), "-q", "-p", "no:cacheprovider", "test_inner.py"], cwd=tmp_path,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "2 passed" in r.stdout and "pytest exit code 0" in r.stdout
    assert "processes: 2, of which ermrl CLI runs: 0" in r.stdout
    rows = {line.split(" | ")[0].lstrip("| "): line for line in r.stdout.splitlines() if line.startswith("| jit(")}
    assert "jit(doubled)" in rows and "jit(tripled)" in rows, r.stdout
    assert rows["jit(doubled)"].split(" | ")[1] == "1"  # one program each
    assert "tests: 2, " in r.stdout
    tests = {line.split(" | ")[0].lstrip("| "): line.split(" | ") for line in r.stdout.splitlines()
             if line.startswith("| test_inner.py::")}
    programs = int(r.stdout.split("programs compiled or fetched: ")[1].split()[0])
    # every program of the run, its own and its child's (jnp.ones and the like are programs too)
    assert tests["test_inner.py::test_compiles_here_and_in_a_subprocess"][3].strip(" |") == str(programs)
    assert tests["test_inner.py::test_compiles_nothing"][3].strip(" |") == "0"


def test_a_failing_run_passes_its_exit_code_on(tmp_path):
    (tmp_path / "test_inner.py").write_text("def test_fails():\n    assert 1 == 2\n")
    r = subprocess.run([sys.executable, str(SCRIPT), "-q", "-p", "no:cacheprovider", "test_inner.py"], cwd=tmp_path,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 1 and "pytest exit code 1" in r.stdout

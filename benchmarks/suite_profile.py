"""Where a pytest run's time goes: JAX compilation and process starts, over every Python process it starts.

Runs pytest with the given arguments, every Python process of the run (pytest-xdist's workers and the CLI
subprocesses that the tests start) reporting through a ``sitecustomize`` hook put first on PYTHONPATH: its wall
time, its command line, and JAX's own compile events (``jax.monitoring``): per jitted function, how many
programs were compiled or fetched from the persistent compilation cache and how long that took, plus the
tracing and MLIR lowering times and the cache's hits and misses. A pytest plugin (``PYTEST_PLUGINS``) records each
test's wall-clock window in its worker, so that the compile events of a worker, and of the CLI runs it starts,
are put to the test that caused them. Then prints a summary: per function, and the tests that compile the most.

The hook registers its listeners when JAX imports its monitoring module, so it changes nothing about when JAX
initializes (ermrl sets the CPU device count before that). Measures, does not time: run it alone.

Example (the default suite, as ``make test`` runs it):
    .venv/bin/python benchmarks/suite_profile.py -q -n 2 -p no:cacheprovider
"""

from __future__ import annotations

import argparse
import collections
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HOOK = '''\
import atexit, importlib.abc, importlib.util, os, sys, time

_OUT = os.environ.get("SUITE_PROFILE_DIR")
if _OUT:
    _T0 = time.time()
    _LINES = []

    def _duration(event, secs, fun_name="", **_):
        _LINES.append(f"D\\t{event}\\t{fun_name}\\t{secs:.6f}\\t{time.time():.3f}")

    def _event(event, **_):
        _LINES.append(f"E\\t{event}")

    def _test(nodeid, start, end):
        """Called by the pytest plugin below in a worker: one test's [start, end] wall clock."""
        _LINES.append(f"T\\t{nodeid}\\t{start:.3f}\\t{end:.3f}")

    class _Finder(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path, target=None):
            if name != "jax._src.monitoring":
                return None
            sys.meta_path.remove(self)
            spec = importlib.util.find_spec(name)
            run = spec.loader.exec_module

            def exec_module(module):
                run(module)
                module.register_event_duration_secs_listener(_duration)
                module.register_event_listener(_event)

            spec.loader.exec_module = exec_module
            return spec

    sys.meta_path.insert(0, _Finder())

    @atexit.register
    def _dump():
        with open(os.path.join(_OUT, f"{os.getpid()}.tsv"), "w") as f:
            f.write(f"P\\t{time.time() - _T0:.3f}\\t{' '.join(sys.argv)[:300]}\\t{os.getppid()}\\n")
            f.write("\\n".join(_LINES) + "\\n")
'''

PLUGIN = '''\
"""Loaded by every pytest process of the profiled run (PYTEST_PLUGINS): hands each test's wall-clock window to the
hook, so that compile events can be put to the test that caused them."""
import time

import pytest
import sitecustomize


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    start = time.time()
    yield
    if hasattr(sitecustomize, "_test"):
        sitecustomize._test(item.nodeid, start, time.time())
'''

COMPILE = "/jax/core/compile/backend_compile_duration"
TRACE = "/jax/core/compile/jaxpr_trace_duration"
LOWER = "/jax/core/compile/jaxpr_to_mlir_module_duration"
HIT = "/jax/compilation_cache/cache_hits"
MISS = "/jax/compilation_cache/cache_misses"


def _read(folder: Path) -> dict[int, dict]:
    """{pid: {"wall", "argv", "ppid", "events": [(event, fun, secs, at)], "counts", "tests": [(nodeid, start, end)]}}
    from the per-process files in ``folder``."""
    procs = {}
    for path in sorted(folder.glob("*.tsv")):
        proc = {"wall": 0.0, "argv": "", "ppid": 0, "events": [], "counts": collections.Counter(), "tests": []}
        for line in path.read_text().splitlines():
            kind, *rest = line.split("\t")
            if kind == "P":
                proc.update(wall=float(rest[0]), argv=rest[1], ppid=int(rest[2]))
            elif kind == "D":
                proc["events"].append((rest[0], rest[1], float(rest[2]), float(rest[3])))
            elif kind == "E":
                proc["counts"][rest[0]] += 1
            elif kind == "T":
                proc["tests"].append((rest[0], float(rest[1]), float(rest[2])))
        procs[int(path.stem)] = proc
    return procs


def per_test(procs: dict[int, dict]) -> dict[str, list[float]]:
    """{test id: [wall s, compile s, tracing + lowering s, programs]}: each compile event of a pytest worker, or of
    a process that a worker started (its CLI runs), is put to the test that ran in that worker at the time."""
    table: dict[str, list[float]] = {}
    for proc in procs.values():
        for nodeid, start, end in proc["tests"]:
            row = table.setdefault(nodeid, [0.0, 0.0, 0.0, 0])
            row[0] += end - start
    for proc in procs.values():
        worker = proc if proc["tests"] else procs.get(proc["ppid"])
        if not worker or not worker["tests"]:
            continue
        for event, _, secs, at in proc["events"]:
            nodeid = next((n for n, start, end in worker["tests"] if start <= at <= end + 1.0), None)
            if nodeid is None:
                continue
            row = table[nodeid]
            if event == COMPILE:
                row[1] += secs
                row[3] += 1
            elif event in (TRACE, LOWER):
                row[2] += secs
    return table


def summarize(folder: Path, top: int = 15) -> str:
    """The summary of the per-process files in ``folder``: totals, the ``top`` functions by compile time, then the
    ``top`` tests by the time spent compiling for them (tracing, lowering and XLA, in-process and in their CLI runs)."""
    procs = _read(folder)
    totals: dict[str, float] = collections.defaultdict(float)
    counts: collections.Counter = collections.Counter()
    per_fun: dict[str, list[float]] = collections.defaultdict(list)
    processes, cli = [], []
    for proc in procs.values():
        processes.append(proc["wall"])
        if "ermrl" in proc["argv"] and "pytest" not in proc["argv"]:
            cli.append(proc["wall"])
        counts.update(proc["counts"])
        for event, fun, secs, _ in proc["events"]:
            totals[event] += secs
            counts[event] += 1
            if event == COMPILE:
                per_fun[fun].append(secs)
    lines = [f"processes: {len(processes)}, of which ermrl CLI runs: {len(cli)} ({sum(cli):.0f} s of wall time in all, "
             f"median {sorted(cli)[len(cli) // 2] if cli else 0:.1f} s)",
             f"programs compiled or fetched: {counts[COMPILE]} ({totals[COMPILE]:.0f} s); persistent cache: "
             f"{counts[HIT]} hits, {counts[MISS]} misses",
             f"tracing: {totals[TRACE]:.0f} s; lowering to MLIR: {totals[LOWER]:.0f} s", "",
             "| function | programs | compile s (sum) | median s |", "|---|---|---|---|"]
    ranked = sorted(per_fun.items(), key=lambda kv: -sum(kv[1]))[:top]
    for fun, secs in ranked:
        lines.append(f"| {fun} | {len(secs)} | {sum(secs):.1f} | {sorted(secs)[len(secs) // 2]:.2f} |")
    tests = per_test(procs)
    if tests:
        spent = sum(r[1] + r[2] for r in tests.values())
        lines += ["", f"tests: {len(tests)}, {sum(r[0] for r in tests.values()):.0f} s in all, of which {spent:.0f} s "
                  "compiling for them (tracing, lowering, XLA)", "",
                  "| test | wall s | compiling s | programs |", "|---|---|---|---|"]
        for nodeid, (wall, comp, trace, n) in sorted(tests.items(), key=lambda kv: -(kv[1][1] + kv[1][2]))[:top]:
            lines.append(f"| {nodeid} | {wall:.1f} | {comp + trace:.1f} | {n} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     usage="%(prog)s [--top N] [PYTEST ARGS ...]")
    parser.add_argument("--top", type=int, default=15, help="functions and tests to list, by compile time")
    args, pytest_args = parser.parse_known_args(argv)
    with tempfile.TemporaryDirectory(prefix="suite-profile-") as tmp:
        hook, out = Path(tmp, "hook"), Path(tmp, "out")
        hook.mkdir()
        out.mkdir()
        (hook / "sitecustomize.py").write_text(HOOK)
        (hook / "suite_profile_plugin.py").write_text(PLUGIN)
        plugins = ",".join(filter(None, ["suite_profile_plugin", os.environ.get("PYTEST_PLUGINS")]))
        env = {**os.environ, "SUITE_PROFILE_DIR": str(out), "PYTEST_PLUGINS": plugins,
               "PYTHONPATH": os.pathsep.join(filter(None, [str(hook), os.environ.get("PYTHONPATH")]))}
        t0 = time.perf_counter()
        code = subprocess.run([sys.executable, "-m", "pytest", *pytest_args], env=env).returncode
        print(f"\npytest exit code {code}, {time.perf_counter() - t0:.0f} s")
        print(summarize(out, args.top))
    return code


if __name__ == "__main__":
    sys.exit(main())

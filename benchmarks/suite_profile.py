"""Where a pytest run's time goes: JAX compilation and process starts, over every Python process it starts.

Runs pytest with the given arguments, every Python process of the run (pytest-xdist's workers and the CLI
subprocesses that the tests start) reporting through a ``sitecustomize`` hook put first on PYTHONPATH: its wall
time, its command line, and JAX's own compile events (``jax.monitoring``): per jitted function, how many
programs were compiled or fetched from the persistent compilation cache and how long that took, plus the
tracing and MLIR lowering times and the cache's hits and misses. Then prints a summary.

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
        _LINES.append(f"D\\t{event}\\t{fun_name}\\t{secs:.6f}")

    def _event(event, **_):
        _LINES.append(f"E\\t{event}")

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
            f.write(f"P\\t{time.time() - _T0:.3f}\\t{' '.join(sys.argv)[:300]}\\n")
            f.write("\\n".join(_LINES) + "\\n")
'''

COMPILE = "/jax/core/compile/backend_compile_duration"
TRACE = "/jax/core/compile/jaxpr_trace_duration"
LOWER = "/jax/core/compile/jaxpr_to_mlir_module_duration"
HIT = "/jax/compilation_cache/cache_hits"
MISS = "/jax/compilation_cache/cache_misses"


def summarize(folder: Path, top: int = 15) -> str:
    """The summary of the per-process files in ``folder``: totals, then the ``top`` functions by compile time."""
    processes, cli = [], []
    totals: dict[str, float] = collections.defaultdict(float)
    counts: collections.Counter = collections.Counter()
    per_fun: dict[str, list[float]] = collections.defaultdict(list)
    for path in sorted(folder.glob("*.tsv")):
        for line in path.read_text().splitlines():
            kind, *rest = line.split("\t")
            if kind == "P":
                wall, argv = float(rest[0]), rest[1]
                processes.append(wall)
                if "ermrl" in argv and "pytest" not in argv:
                    cli.append(wall)
            elif kind == "D":
                event, fun, secs = rest[0], rest[1], float(rest[2])
                totals[event] += secs
                counts[event] += 1
                if event == COMPILE:
                    per_fun[fun].append(secs)
            elif kind == "E":
                counts[rest[0]] += 1
    lines = [f"processes: {len(processes)}, of which ermrl CLI runs: {len(cli)} ({sum(cli):.0f} s of wall time in all, "
             f"median {sorted(cli)[len(cli) // 2] if cli else 0:.1f} s)",
             f"programs compiled or fetched: {counts[COMPILE]} ({totals[COMPILE]:.0f} s); persistent cache: "
             f"{counts[HIT]} hits, {counts[MISS]} misses",
             f"tracing: {totals[TRACE]:.0f} s; lowering to MLIR: {totals[LOWER]:.0f} s", "",
             "| function | programs | compile s (sum) | median s |", "|---|---|---|---|"]
    ranked = sorted(per_fun.items(), key=lambda kv: -sum(kv[1]))[:top]
    for fun, secs in ranked:
        lines.append(f"| {fun} | {len(secs)} | {sum(secs):.1f} | {sorted(secs)[len(secs) // 2]:.2f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     usage="%(prog)s [--top N] [PYTEST ARGS ...]")
    parser.add_argument("--top", type=int, default=15, help="functions to list, by compile time")
    args, pytest_args = parser.parse_known_args(argv)
    with tempfile.TemporaryDirectory(prefix="suite-profile-") as tmp:
        hook, out = Path(tmp, "hook"), Path(tmp, "out")
        hook.mkdir()
        out.mkdir()
        (hook / "sitecustomize.py").write_text(HOOK)
        env = {**os.environ, "SUITE_PROFILE_DIR": str(out),
               "PYTHONPATH": os.pathsep.join(filter(None, [str(hook), os.environ.get("PYTHONPATH")]))}
        t0 = time.perf_counter()
        code = subprocess.run([sys.executable, "-m", "pytest", *pytest_args], env=env).returncode
        print(f"\npytest exit code {code}, {time.perf_counter() - t0:.0f} s")
        print(summarize(out, args.top))
    return code


if __name__ == "__main__":
    sys.exit(main())

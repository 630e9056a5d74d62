"""One population trained in several processes (``TrainConfig.processes``; host-loop backends only).

On the ``mujoco`` and ``host`` backends a process alternates, at every env step, a jitted call and the physics, so
it leaves part of a small machine's cores idle (docs/benchmarks.md, "MuJoCo populations: two processes at once
against one"). :func:`run_split` trains the population's agents in ``processes`` contiguous parts at once: the
first in this process, each other in a fresh interpreter (``python -c``, as the env workers of
:mod:`ermrl.envs.host_groups`: fork is unsafe under JAX's threads) with its own JAX devices and envs. An agent
trains the same in any population (:mod:`ermrl.training.programs`), so the joined Results are those of one
process, agent for agent.

A part's snapshot (``Trainer.run(snapshot=PATH)``) is PATH for the first part and ``PATH.partK`` for part K, so
a stopped run resumes every part with the same ``processes``. A helper process ends when its parent does (it
watches its parent's pid), and the parent stops its helpers when it stops (Ctrl-C, SIGTERM, an error).
"""

from __future__ import annotations

import dataclasses
import socket
import subprocess
import sys
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Callable

def part_bounds(size: int, parts: int) -> list[int]:
    """The agent index where each of ``parts`` contiguous parts starts, then ``size``: part sizes differ by at
    most one, and there are never more parts than agents."""
    parts = max(1, min(parts, size))
    return [size * k // parts for k in range(parts + 1)]


def part_snapshot(snapshot: Path | None, k: int) -> Path | None:
    """The snapshot file of part ``k`` (None without snapshots)."""
    if snapshot is None or k == 0:
        return snapshot
    return snapshot.with_name(f"{snapshot.name}.part{k}")


class _Helper:
    """One part trained in a fresh interpreter; ``result`` waits for its Results."""

    def __init__(self, config, population, snapshot: Path | None, snapshot_every_s: float):
        parent, child = socket.socketpair()
        code = f"from ermrl.training.part_process import serve; serve({child.fileno()})"
        self.process = subprocess.Popen([sys.executable, "-c", code], pass_fds=[child.fileno()])
        child.close()
        self.conn = Connection(parent.detach())
        self.conn.send((config, population, snapshot, snapshot_every_s))

    def result(self, log: Callable[[str], None] | None):
        """The part's Results; a helper's log lines go to ``log`` meanwhile. RuntimeError if it failed or died."""
        while True:
            try:
                status, value = self.conn.recv()
            except (EOFError, ConnectionResetError):
                code = self.process.wait(timeout=5)
                raise RuntimeError(f"a training process died (exit code {code}); see its error above") from None
            if status == "log":
                if log is not None:
                    log(value)
                continue
            if status == "error":
                raise RuntimeError(f"training process: {value}")
            self.process.wait(timeout=60)
            return value

    def stop(self) -> None:
        """Ends the helper if it still runs (the parent stopped first)."""
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait(timeout=10)
        self.conn.close()


def run_split(run_here: Callable, config, population, processes: int, progress_fn=None,
              snapshot: Path | None = None, snapshot_every_s: float = 300.0, log: Callable[[str], None] | None = None):
    """Trains ``population`` in ``processes`` parts at once and returns the Results of all its agents, in order.
    ``run_here(part, progress_fn, snapshot, snapshot_every_s, log)`` trains the first part in this process;
    ``progress_fn`` sees its progress scaled to the whole population. ``compile_s`` and ``train_s`` are the longest
    part's (the parts run at the same time)."""
    from ermrl.errors import ConfigError
    from ermrl.training import snapshots
    from ermrl.training.results import Results

    bounds = part_bounds(population.size, processes)
    parts = [_slice(population, a, b) for a, b in zip(bounds[:-1], bounds[1:])]
    for k in range(1, len(parts)):
        path = part_snapshot(snapshot, k)
        if path is not None and (path.is_dir() or path.exists() and not snapshots.is_snapshot(path)):
            raise ConfigError(f"{path} is in the way: a part of the run keeps its snapshot there, and it is not one "
                              "(or is damaged); move it away")
    one = dataclasses.replace(config, processes=1)
    helpers: list[_Helper] = []
    try:
        for k, part in enumerate(parts[1:], start=1):
            helpers.append(_Helper(one, part, part_snapshot(snapshot, k), snapshot_every_s))
        scale = population.size / parts[0].size

        def scaled(p):
            progress_fn(dataclasses.replace(p, agent_steps=round(p.agent_steps * scale),
                                            total_agent_steps=round(p.total_agent_steps * scale)))

        results = [run_here(parts[0], scaled if progress_fn is not None else None, snapshot, snapshot_every_s, log)]
        results += [h.result(log) for h in helpers]
    finally:
        for h in helpers:
            h.stop()
    for k in range(1, len(parts)):
        path = part_snapshot(snapshot, k)
        if path is not None:
            path.unlink(missing_ok=True)
    return dataclasses.replace(Results.concat(results), compile_s=max(r.compile_s for r in results),
                               train_s=max(r.train_s for r in results))


def _slice(population, a: int, b: int):
    """Agents [a, b) of ``population``."""
    from ermrl.agent import Phi
    from ermrl.training.config import Population

    return Population(seeds=population.seeds[a:b], phi=Phi(*(f[a:b] for f in population.phi)),
                      learning_rate=population.learning_rate[a:b])

"""One population trained in several processes (``TrainConfig.processes``; host-loop backends only).

On the ``mujoco`` and ``host`` backends a process alternates, at every env step, a jitted call and the physics, so
it leaves part of a small machine's cores idle (docs/benchmarks.md, "MuJoCo populations: one process, two at
once, and `--processes 2`"). :func:`run_split` trains the population's agents in ``processes`` contiguous parts
at once: the first in this process, each other in a fresh interpreter (:mod:`ermrl.child_interpreter`) with its
own JAX devices and envs. An agent trains the same in any population (:mod:`ermrl.training.programs`), so the
joined Results are those of one process, agent for agent.

A part's snapshot (``Trainer.run(snapshot=PATH)``) is PATH for the first part and ``PATH.partK`` for part K, so
a stopped run resumes every part with the same ``processes``. A helper process ends when its parent does (it
watches its parent's pid), and the parent stops its helpers when it stops (Ctrl-C, SIGTERM, an error).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Callable

from ermrl.child_interpreter import ChildInterpreter

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
    """One part trained in a fresh interpreter (:mod:`ermrl.training.part_process`)."""

    def __init__(self, config, population, snapshot: Path | None, snapshot_every_s: float):
        self.child = ChildInterpreter("ermrl.training.part_process", "a training process")
        self.child.send((config, population, snapshot, snapshot_every_s))
        self.results = None

    def _take(self, log: Callable[[str], None] | None) -> None:
        """Receives one message: a log line goes to ``log``, the Results are kept; RuntimeError if the part
        failed, :class:`~ermrl.child_interpreter.ChildDied` if its process died."""
        status, value = self.child.receive()
        if status == "log":
            if log is not None:
                log(value)
        elif status == "error":
            raise RuntimeError(f"training process: {value}")
        else:
            self.results = value

    def drain(self, log: Callable[[str], None] | None) -> None:
        """Takes every message already sent, without waiting: a failed or dead helper raises at once."""
        while self.results is None and self.child.ready():
            self._take(log)

    def result(self, log: Callable[[str], None] | None):
        """Waits for the part's Results (log lines go to ``log`` meanwhile)."""
        while self.results is None:
            self._take(log)
        self.child.process.wait(timeout=60)
        return self.results

    def stop(self) -> None:
        """Ends the helper if it still runs (the parent stopped first)."""
        if self.child.process.poll() is None:
            self.child.process.kill()
        self.child.close()


def run_split(run_here: Callable, config, population, processes: int, progress_fn=None,
              snapshot: Path | None = None, snapshot_every_s: float = 300.0, log: Callable[[str], None] | None = None):
    """Trains ``population`` in ``processes`` parts at once and returns the Results of all its agents, in order.
    ``run_here(part, progress_fn, snapshot, snapshot_every_s, log)`` trains the first part in this process;
    ``progress_fn`` sees its progress scaled to the whole population. ``compile_s`` and ``train_s`` are the longest
    part's (the parts run at the same time). The helpers' log lines reach ``log`` as they come (seen after each
    iteration of the first part), and a helper that fails or dies stops the whole run there, with its error."""
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

        def each_iteration(p):  # of the first part: the helpers' news, then the progress over the population
            for h in helpers:
                h.drain(log)
            if progress_fn is not None:
                progress_fn(dataclasses.replace(p, agent_steps=round(p.agent_steps * scale),
                                                total_agent_steps=round(p.total_agent_steps * scale)))

        results = [run_here(parts[0], each_iteration, snapshot, snapshot_every_s, log)]
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

"""Progress displays for training and evolution: steps, agent-steps/s and ETA. The library reports through
``progress_fn`` callbacks; only the CLI decides to draw.

On a terminal the displays are rich progress bars redrawn in place. When the stream is not a terminal (a pipe,
a log file, CI), they print plain whole lines instead: no control codes, nothing cut to the terminal width, at
most one line every ``interval_s`` seconds, plus one at the end of each phase (a training run, one env's
population within a generation, a told generation)."""

from __future__ import annotations

import sys
import time

from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

from ermrl.model_labels import param_name
from ermrl.training import Progress as TrainProgress

LINE_INTERVAL_S = 10.0
"""Seconds between two progress lines when the stream is not a terminal (phase ends are always printed)."""


class LineLog:
    """Whole progress lines at a steady pace: ``offer`` a line after every update; it is printed when
    ``interval_s`` seconds passed since the last printed line, when ``force`` (a phase ended) or when it is the
    first; ``flush`` prints the last offered line if it was held back; ``say`` prints a line at once."""

    def __init__(self, stream, interval_s: float = LINE_INTERVAL_S):
        self.stream, self.interval_s = stream, interval_s
        self._last_print: float | None = None
        self._pending: str | None = None

    def offer(self, line: str, force: bool = False) -> None:
        self._pending = line
        now = time.monotonic()
        if force or self._last_print is None or now - self._last_print >= self.interval_s:
            self.flush()

    def flush(self) -> None:
        if self._pending is not None:
            self.say(self._pending)
            self._pending, self._last_print = None, time.monotonic()

    def say(self, line: str) -> None:
        """Prints ``line`` now, outside the pace (the first update still prints at once)."""
        sys.stdout.flush()  # results printed on stdout before this line come first in a merged log
        self.stream.write(line + "\n")
        self.stream.flush()


def _lines(console: Console, enabled: bool, interval_s: float) -> LineLog | None:
    """A LineLog on the console's stream when it is not a terminal (and the display is enabled), else None."""
    return LineLog(console.file, interval_s) if enabled and not console.is_terminal else None


class TrainingBar:
    """Context manager whose ``update`` is a ``progress_fn``. Draws to stderr; silent when ``enabled`` is False."""

    def __init__(self, description: str, console: Console | None = None, enabled: bool = True,
                 interval_s: float = LINE_INTERVAL_S):
        self.console = console or Console(stderr=True)
        self.enabled = enabled
        self.description = description
        self._lines = _lines(self.console, enabled, interval_s)
        self._bar = Progress(
            TextColumn("[bold]{task.description}"), BarColumn(bar_width=20), TextColumn("{task.fields[steps]}"),
            TextColumn("{task.fields[rate]}"), TextColumn("ETA"), TimeRemainingColumn(),
            console=self.console, disable=not enabled or self._lines is not None, transient=False,
        )
        self._task = None

    def __enter__(self):
        self._bar.__enter__()
        self._task = self._bar.add_task(self.description + " (compiling)", total=None, rate="", steps="")
        if self._lines is not None:
            self._lines.say(f"{self.description}: compiling")
        return self

    def __exit__(self, *exc):
        self._bar.__exit__(*exc)
        if self._lines is not None:
            self._lines.flush()

    def update(self, p: TrainProgress) -> None:
        rate = p.agent_steps / p.elapsed_s if p.elapsed_s > 0 else 0.0
        steps = f"{p.agent_steps / 1e3:,.0f}k/{p.total_agent_steps / 1e3:,.0f}k steps"
        if self._lines is not None:
            left = (p.total_agent_steps - p.agent_steps) / rate if rate > 0 else 0.0
            self._lines.offer(f"{self.description}: {steps} ({100 * p.agent_steps / p.total_agent_steps:.0f}%) | "
                              f"{rate:,.0f} agent-steps/s | elapsed {_hms(p.elapsed_s)} + compile "
                              f"{p.compile_s:.0f} s | ETA {_hms(left)}", force=p.agent_steps >= p.total_agent_steps)
            return
        self._bar.update(self._task, description=self.description, total=p.total_agent_steps,
                         completed=p.agent_steps, rate=f"{rate:,.0f} agent-steps/s (compiled in {p.compile_s:.0f} s)",
                         steps=steps)


class EvolutionBar:
    """``progress_fn`` for ``evolve``: generation, trials done of total, best fitness with its Φ,
    agent-steps/s, and an ETA for the whole study."""

    def __init__(self, total_trials: int, popsize: int, n_envs: int = 1, console: Console | None = None,
                 enabled: bool = True, interval_s: float = LINE_INTERVAL_S):
        self.console = console or Console(stderr=True)
        self.total_trials, self.popsize, self.n_envs = total_trials, popsize, n_envs
        self._lines = _lines(self.console, enabled, interval_s)
        self._bar = Progress(TextColumn("{task.description}"), BarColumn(bar_width=20), TextColumn("{task.fields[rate]}"),
                             TextColumn("study ETA {task.fields[eta]}"), console=self.console,
                             disable=not enabled or self._lines is not None)
        self._task = None
        self._gen_start: float | None = None
        self._gen_seconds: list[float] = []

    def __enter__(self):
        self._bar.__enter__()
        self._task = self._bar.add_task("starting", total=None, rate="", eta="?")
        return self

    def __exit__(self, *exc):
        self._bar.__exit__(*exc)
        if self._lines is not None:
            self._lines.flush()

    def update(self, p) -> None:
        best = "none yet" if p.best_value is None else f"{p.best_value:.1f} (" + ", ".join(
            f"{param_name(k)} {v:.3g}" for k, v in p.best_params.items()) + ")"
        desc = f"gen {p.generation} | {p.completed}/{p.trials} trials | best {best}"
        if self.n_envs > 1 and p.train is not None:
            desc += f" | {p.env_id}"
        if p.train is None:  # a generation was told
            if self._gen_start is not None:
                self._gen_seconds.append(time.perf_counter() - self._gen_start)
            self._gen_start = None
            if self._lines is not None:
                eta = self._mean_gen_s() * -(-(p.trials - p.completed) // self.popsize) if self._gen_seconds else None
                self._lines.offer(f"{desc} | generation done | study ETA {'?' if eta is None else _hms(eta)}",
                                  force=True)
                return
            self._bar.update(self._task, description=desc)
            return
        if self._gen_start is None:
            # compile excluded: later generations of the same size reuse the program
            self._gen_start = time.perf_counter() - p.train.elapsed_s
        rate = p.train.agent_steps / p.train.elapsed_s if p.train.elapsed_s > 0 else 0.0
        gens_left = -(-(p.trials - p.completed) // self.popsize)
        per_gen = self._mean_gen_s() if self._gen_seconds else \
            self.n_envs * p.train.elapsed_s * p.train.total_agent_steps / max(p.train.agent_steps, 1)
        left_this = per_gen * (1 - p.train.agent_steps / p.train.total_agent_steps) / self.n_envs
        eta = left_this + per_gen * (gens_left - 1)
        if self._lines is not None:
            self._lines.offer(f"{desc} | training {100 * p.train.agent_steps / p.train.total_agent_steps:.0f}% | "
                              f"{rate:,.0f} agent-steps/s | study ETA {_hms(eta)}",
                              force=p.train.agent_steps >= p.train.total_agent_steps)
            return
        self._bar.update(self._task, description=desc, total=p.train.total_agent_steps, completed=p.train.agent_steps,
                         rate=f"{rate:,.0f} agent-steps/s", eta=_hms(eta))

    def _mean_gen_s(self) -> float:
        return sum(self._gen_seconds) / len(self._gen_seconds)


def _hms(seconds: float) -> str:
    seconds = max(0, int(seconds))
    return f"{seconds // 3600}:{seconds % 3600 // 60:02d}:{seconds % 60:02d}"

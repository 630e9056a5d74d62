"""A rich progress bar for training: steps, agent-steps/s and ETA. The library reports through
``progress_fn`` callbacks; only the CLI decides to draw."""

from __future__ import annotations

from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

from ermrl.training import Progress as TrainProgress


class TrainingBar:
    """Context manager whose ``update`` is a ``progress_fn``. Draws to stderr; silent when ``enabled`` is False."""

    def __init__(self, description: str, console: Console | None = None, enabled: bool = True):
        self.console = console or Console(stderr=True)
        self.enabled = enabled
        self.description = description
        self._bar = Progress(
            TextColumn("[bold]{task.description}"), BarColumn(bar_width=20), TextColumn("{task.fields[steps]}"),
            TextColumn("{task.fields[rate]}"), TextColumn("ETA"), TimeRemainingColumn(),
            console=self.console, disable=not enabled, transient=False,
        )
        self._task = None

    def __enter__(self):
        self._bar.__enter__()
        self._task = self._bar.add_task(self.description + " (compiling)", total=None, rate="", steps="")
        return self

    def __exit__(self, *exc):
        self._bar.__exit__(*exc)

    def update(self, p: TrainProgress) -> None:
        rate = p.agent_steps / p.elapsed_s if p.elapsed_s > 0 else 0.0
        self._bar.update(self._task, description=self.description, total=p.total_agent_steps,
                         completed=p.agent_steps, rate=f"{rate:,.0f} agent-steps/s",
                         steps=f"{p.agent_steps / 1e3:,.0f}k/{p.total_agent_steps / 1e3:,.0f}k steps")


class EvolutionBar:
    """``progress_fn`` for ``evolve``: generation, trials done of total, best fitness with its Φ,
    agent-steps/s, and an ETA for the whole study."""

    def __init__(self, total_trials: int, popsize: int, n_envs: int = 1, console: Console | None = None,
                 enabled: bool = True):
        self.console = console or Console(stderr=True)
        self.total_trials, self.popsize, self.n_envs = total_trials, popsize, n_envs
        self._bar = Progress(TextColumn("{task.description}"), BarColumn(bar_width=20), TextColumn("{task.fields[rate]}"),
                             TextColumn("study ETA {task.fields[eta]}"), console=self.console, disable=not enabled)
        self._task = None
        self._gen_start: float | None = None
        self._gen_seconds: list[float] = []

    def __enter__(self):
        self._bar.__enter__()
        self._task = self._bar.add_task("starting", total=None, rate="", eta="?")
        return self

    def __exit__(self, *exc):
        self._bar.__exit__(*exc)

    def update(self, p) -> None:
        import time

        best = "none yet" if p.best_value is None else f"{p.best_value:.1f} (" + ", ".join(
            f"{k} {v:.3g}" for k, v in p.best_params.items()) + ")"
        desc = f"gen {p.generation} | {p.completed}/{p.trials} trials | best {best}"
        if self.n_envs > 1 and p.train is not None:
            desc += f" | {p.env_id}"
        if p.train is None:  # a generation was told
            if self._gen_start is not None:
                self._gen_seconds.append(time.perf_counter() - self._gen_start)
            self._gen_start = None
            self._bar.update(self._task, description=desc)
            return
        if self._gen_start is None:
            self._gen_start = time.perf_counter() - p.train.elapsed_s - p.train.compile_s
        rate = p.train.agent_steps / p.train.elapsed_s if p.train.elapsed_s > 0 else 0.0
        gens_left = -(-(p.trials - p.completed) // self.popsize)
        per_gen = (sum(self._gen_seconds) / len(self._gen_seconds)) if self._gen_seconds else \
            self.n_envs * p.train.elapsed_s * p.train.total_agent_steps / max(p.train.agent_steps, 1)
        left_this = per_gen * (1 - p.train.agent_steps / p.train.total_agent_steps) / self.n_envs
        eta = left_this + per_gen * (gens_left - 1)
        self._bar.update(self._task, description=desc, total=p.train.total_agent_steps, completed=p.train.agent_steps,
                         rate=f"{rate:,.0f} agent-steps/s", eta=_hms(eta))


def _hms(seconds: float) -> str:
    seconds = max(0, int(seconds))
    return f"{seconds // 3600}:{seconds % 3600 // 60:02d}:{seconds % 60:02d}"

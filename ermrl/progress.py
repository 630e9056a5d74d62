"""A rich progress bar for training: steps, agent-steps/s and ETA. The library reports through
``progress_fn`` callbacks; only the CLI decides to draw."""

from __future__ import annotations

from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

from ermrl.train import Progress as TrainProgress


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

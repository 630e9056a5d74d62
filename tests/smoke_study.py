"""The smoke study that several test modules share: CartPoleNoVel with 1 reservoir from the registry's
partial-observability experiment, evolved, selected and tested at the `smoke` scale with a 2-seed test budget."""

from pathlib import Path

from ermrl.experiments import runner

from cli_runs import ermrl as cli

EXPERIMENT, STUDY = "partial-observability", "cartpole-1res"
BUDGET = runner.TestBudget(seeds=2, timesteps=4096, learning_rates=(1e-4, 3e-4))
FLAGS = ["--test-seeds", "2", "--test-timesteps", "4096", "--test-learning-rates", "1e-4", "3e-4"]
RUN = ["experiment", "run", EXPERIMENT, "--only", STUDY, "--scale", "smoke", "--quiet", "--no-estimate"]


def evolve(folder: Path) -> Path:
    """The study evolved, selected and tested by the CLI into FOLDER with the budget flags, uninterrupted."""
    r = cli(*RUN, "--out", str(folder), *FLAGS)
    assert r.returncode == 0, r.stderr
    return folder

"""TensorBoard logs of training runs, under stable-baselines3's tag names, written after training.

One run folder per agent, ``LOGDIR/<label>_seed<seed>`` (like SB3's ``PPO_1``), whose global step is the agent's
env-step count (summed over its envs, SB3's ``num_timesteps``). Tags, one point per PPO update:

- ``rollout/ep_rew_mean``, ``rollout/ep_len_mean``: mean return and length of the agent's last 100 episodes
  (:meth:`Results.curves`); no point before its first episode, as in SB3;
- ``time/fps``: the agent's env steps per second of training since it started (compile excluded), from a
  :class:`Timing` progress_fn; the agents of one population train together, so they share it;
- ``train/policy_gradient_loss``, ``train/value_loss``, ``train/entropy_loss``, ``train/approx_kl``,
  ``train/clip_fraction``: the PPO update's diagnostics, averaged over its epochs and minibatches.
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np

from ermrl import storage
from ermrl.errors import ConfigError

TRAIN_TAGS = {"policy_loss": ("train/policy_gradient_loss", 1.0), "value_loss": ("train/value_loss", 1.0),
              "entropy": ("train/entropy_loss", -1.0), "approx_kl": ("train/approx_kl", 1.0),
              "clip_fraction": ("train/clip_fraction", 1.0)}
"""Results.metrics name -> (SB3 tag, sign): SB3 logs the entropy loss, i.e. minus the entropy."""


def check_logdir(path: Path | str) -> Path:
    """``path`` if TensorBoard runs can be written there; one-line ConfigError otherwise (before any training)."""
    return storage.check_folder(path, "--tensorboard")


class Timing:
    """A ``progress_fn`` that records the training wall time at every update (for ``time/fps``); calls ``then``
    (another progress_fn, e.g. a progress bar's) with each report too."""

    def __init__(self, then=None):
        self.then = then
        self.elapsed_s: list[float] = []
        """Seconds since training started (compile excluded), one per update so far."""

    def __call__(self, progress) -> None:
        self.elapsed_s.append(float(progress.elapsed_s))
        if self.then is not None:
            self.then(progress)


class Timings:
    """A progress factory (label -> progress_fn, as ``run_test_phase`` takes) that gives each population a
    :class:`Timing` around ``then(label)``; ``elapsed_s`` {label: its update times}."""

    def __init__(self, then=None):
        self.then = then
        self.elapsed_s: dict[str, list[float]] = {}

    def __call__(self, label: str) -> Timing:
        timing = Timing(self.then(label) if self.then is not None else None)
        self.elapsed_s[label] = timing.elapsed_s
        return timing

    def of(self, label: str) -> list[float] | None:
        """The update times of the population that trained the model ``label``: its own, or its first word's
        (the ER-MRL models of several learning rates train as one population, "ER-MRL"); None when it did not
        train here (e.g. kept from an earlier run)."""
        return self.elapsed_s.get(label, self.elapsed_s.get(label.split(" ")[0]))


def run_name(label: str, seed: int) -> str:
    """``<label>_seed<seed>`` with every run of characters other than letters, digits, '.', '-' replaced by '_'."""
    return f"{re.sub(r'[^A-Za-z0-9.-]+', '_', label).strip('_') or 'run'}_seed{int(seed)}"


def _fresh(folder: Path, taken: set[Path]) -> Path:
    """``folder``, or ``folder_2``, ``folder_3``, ... when it already exists: a rerun never mixes two runs' events."""
    out, n = folder, 1
    while out.exists() or out in taken:
        n += 1
        out = folder.with_name(f"{folder.name}_{n}")
    taken.add(out)
    return out


def write_scalars(logdir: Path | str, label: str, seeds, steps, scalars: dict[str, np.ndarray]) -> list[Path]:
    """Writes one run folder per agent under ``logdir`` and returns them, in agent order.

    ``seeds`` (A,); ``steps`` (I,) the global steps; ``scalars`` {tag: (A, I) values}, non-finite values skipped."""
    from tensorboardX import SummaryWriter

    logdir, seeds, steps = Path(check_logdir(logdir)), np.asarray(seeds), np.asarray(steps)
    taken: set[Path] = set()
    folders = []
    for a, seed in enumerate(seeds):
        folder = _fresh(logdir / run_name(label, seed), taken)
        with storage.staged_folder(folder) as stage:  # a run folder appears complete, or not at all
            writer = SummaryWriter(logdir=str(stage))
            try:
                for tag, values in scalars.items():
                    row = np.asarray(values, np.float64)[a]
                    for step, v in zip(steps, row):
                        if np.isfinite(v):
                            writer.add_scalar(tag, float(v), int(step))
            finally:
                writer.close()
        folders.append(folder)
    return folders


def fps(steps, elapsed_s) -> np.ndarray | None:
    """(I,) env steps per second of one agent at each update, from the (I,) per-agent ``steps`` and the (I,)
    training wall times of a :class:`Timing`; None when the timing does not cover every update."""
    steps, elapsed = np.asarray(steps, np.float64), np.asarray(elapsed_s, np.float64)
    if elapsed.shape != steps.shape:
        return None
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(elapsed > 0, steps / elapsed, np.nan)


def results_scalars(results, elapsed_s=None) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """(steps (I,), {tag: (A, I)}) of a :class:`~ermrl.training.results.Results`, with ``time/fps`` when
    ``elapsed_s`` (a :class:`Timing`'s, (I,)) is given."""
    from ermrl.training.results import Episodes

    steps, rew = results.curves()
    # the same last-100 window over episode lengths: curves() of the episodes with their lengths as returns
    as_lengths = dataclasses.replace(results, episodes=[Episodes(e.timestep, e.length.astype(np.float64), e.length)
                                                        for e in results.episodes])
    scalars = {"rollout/ep_rew_mean": rew, "rollout/ep_len_mean": as_lengths.curves()[1]}
    rate = fps(steps, elapsed_s) if elapsed_s is not None else None
    if rate is not None:
        scalars["time/fps"] = np.broadcast_to(rate, rew.shape)
    for name, (tag, sign) in TRAIN_TAGS.items():
        m = results.metrics.get(name)
        if m is not None and np.shape(m) == rew.shape:
            scalars[tag] = sign * np.asarray(m, np.float64)
    return steps, scalars


def write_results(logdir: Path | str, results, label: str, elapsed_s=None) -> list[Path]:
    """One run folder per agent of ``results`` (see the module doc); returns them in agent order."""
    steps, scalars = results_scalars(results, elapsed_s)
    return write_scalars(logdir, label, results.seeds, steps, scalars)

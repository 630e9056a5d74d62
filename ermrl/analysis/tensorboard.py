"""TensorBoard logs of training runs, under stable-baselines3's tag names, written after training.

One run folder per agent, ``LOGDIR/<label>_seed<seed>`` (like SB3's ``PPO_1``), whose global step is the agent's
env-step count (summed over its envs, SB3's ``num_timesteps``). Tags, one point per PPO update:

- ``rollout/ep_rew_mean``, ``rollout/ep_len_mean``: mean return and length of the agent's last 100 episodes
  (:meth:`Results.curves`); no point before its first episode, as in SB3;
- ``time/fps``: the agent's env steps per second of training since it started (compile excluded), from the
  update times the trainer keeps in ``Results.metrics`` (``WALL_S``); agents trained together share it, and a
  model trained in groups of agents (``--agents-per-run``) has each group's own;
- ``train/policy_gradient_loss``, ``train/value_loss``, ``train/entropy_loss``, ``train/approx_kl``,
  ``train/clip_fraction``: the PPO update's diagnostics, averaged over its epochs and minibatches.
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np

from ermrl import storage

TRAIN_TAGS = {"policy_loss": ("train/policy_gradient_loss", 1.0), "value_loss": ("train/value_loss", 1.0),
              "entropy": ("train/entropy_loss", -1.0), "approx_kl": ("train/approx_kl", 1.0),
              "clip_fraction": ("train/clip_fraction", 1.0)}
"""Results.metrics name -> (SB3 tag, sign): SB3 logs the entropy loss, i.e. minus the entropy."""


def check_logdir(logdir: Path | str) -> Path:
    """``logdir`` if TensorBoard runs can be written there; one-line ConfigError otherwise (before any training)."""
    return storage.check_folder(logdir, "`logdir`")


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


def fps(steps, wall_s) -> np.ndarray | None:
    """(A, I) env steps per second of each agent at each update, from the (I,) per-agent ``steps`` and the (A, I)
    training wall times (``Results.metrics[WALL_S]``); None when they do not cover every update."""
    steps, wall = np.asarray(steps, np.float64), np.asarray(wall_s, np.float64)
    if wall.ndim != 2 or wall.shape[1] != steps.shape[0]:
        return None
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(wall > 0, steps / wall, np.nan)


def results_scalars(results) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """(steps (I,), {tag: (A, I)}) of a :class:`~ermrl.training.results.Results`, with ``time/fps`` when its
    metrics hold the update times (results saved before they were kept have none)."""
    from ermrl.training.results import WALL_S, Episodes

    steps, rew = results.curves()
    # the same last-100 window over episode lengths: curves() of the episodes with their lengths as returns
    as_lengths = dataclasses.replace(results, episodes=[Episodes(e.timestep, e.length.astype(np.float64), e.length)
                                                        for e in results.episodes])
    scalars = {"rollout/ep_rew_mean": rew, "rollout/ep_len_mean": as_lengths.curves()[1]}
    wall = results.metrics.get(WALL_S)
    rate = fps(steps, wall) if wall is not None else None
    if rate is not None and rate.shape == rew.shape:
        scalars["time/fps"] = rate
    for name, (tag, sign) in TRAIN_TAGS.items():
        m = results.metrics.get(name)
        if m is not None and np.shape(m) == rew.shape:
            scalars[tag] = sign * np.asarray(m, np.float64)
    return steps, scalars


def write_results(logdir: Path | str, results, label: str) -> list[Path]:
    """One run folder per agent of ``results`` (see the module doc); returns them in agent order."""
    steps, scalars = results_scalars(results)
    return write_scalars(logdir, label, results.seeds, steps, scalars)

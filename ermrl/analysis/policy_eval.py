"""The trained policy evaluated after training: each saved agent's return over fresh episodes, by default with its
deterministic action (the Gaussian mean, or the argmax of the logits).

The paper's score, and ermrl's *final*, is the mean return of the last 10 *training* episodes, whose actions are
drawn from the stochastic policy. Benchmarks such as rl-zoo's report instead the mean return of the trained agent
over evaluation episodes with its deterministic policy. This module measures that second number for the same
agents, so that a score can be set beside a benchmark measured the same way; it does not change the fitness.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Callable

import numpy as np

from ermrl.errors import ConfigError


def agent_returns(agent_file: Path | str, episodes: int, first_seed: int = 0, deterministic: bool = True,
                  max_steps: int | None = None) -> tuple[dict, np.ndarray]:
    """(the agent file's meta record, returns (episodes,)) of one saved agent over ``episodes`` episodes of its
    env (velocities deleted for NoVel ids), episode i reset with env seed ``first_seed + i``. Stochastic actions
    are drawn with a Generator seeded by the agent's training seed, so a rerun gives the same returns."""
    from ermrl.analysis.context import record_episode
    from ermrl.saved_agent import load_agent

    if episodes < 1:
        raise ConfigError(f"episodes must be >= 1, got {episodes}")
    agent = load_agent(agent_file)
    agent.reset(sampling_seed=agent.seed)
    env = agent.make_env()
    try:
        returns = [record_episode(agent, env, first_seed + i, max_steps, deterministic)[2].sum()
                   for i in range(episodes)]
    finally:
        env.close()
    return agent.meta, np.asarray(returns, float)


def evaluate_runs(sources: dict[str, list[Path]], episodes: int = 10, first_seed: int = 0,
                  deterministic: bool = True, max_steps: int | None = None,
                  log: Callable[[str], None] | None = None) -> tuple[str, list[dict]]:
    """Evaluates every saved agent of each named source (label -> agent files, e.g. a run's ``agents/``).

    Returns a Markdown table, one row per source: over its agents (one value per agent, the mean of its
    evaluation episodes), the evaluation's mean ± std and IQM [95% CI], the same for the training score *final*
    recorded in the agent files, and the paired difference evaluation − final; and the per-agent rows (run,
    agent, seed, final, the evaluation's mean and its episodes' returns). ``log`` gets a line per agent evaluated
    (its mean, the time so far and an estimate of the time left)."""
    from ermrl.analysis.statistics import format_ci, paired_difference, summarize

    how = "deterministic" if deterministic else "stochastic"
    lines = [f"| run | agents | evaluation ({how}, {episodes} episodes each): mean ± std | IQM [95% CI] | "
             "final (last 10 training episodes): mean ± std | IQM [95% CI] | evaluation − final, paired [95% CI] |",
             "|---|---:|---|---|---|---|---|"]
    rows = []
    for label, files in sources.items():
        if not files:
            raise ConfigError(f"{label} holds no saved agent; train with `save_agents` (the default) first")
    total, start = sum(map(len, sources.values())), time.monotonic()
    for label, files in sources.items():
        found = []
        for f in files:
            meta, returns = agent_returns(f, episodes, first_seed, deterministic, max_steps)
            found.append({"run": label, "agent": str(f), "seed": int(meta["seed"]), "final": meta.get("fitness"),
                          "evaluation": float(returns.mean()), "returns": returns.tolist()})
            if log is not None:
                done, spent = len(rows) + len(found), time.monotonic() - start
                log(f"[{done}/{total}] {f}: {returns.mean():.1f} over {episodes} episodes "
                    f"({spent:.0f} s, ≈ {spent / done * (total - done):.0f} s left)")
        rows += found
        evaluation, final = [r["evaluation"] for r in found], [r["final"] for r in found]  # final: None if diverged
        cells, on_final = [], summarize(final)
        for s in (summarize(evaluation), on_final):
            cells += ["—" if s.mean is None else f"{s.mean:.1f} ± {s.std:.1f}", format_ci(s.iqm, s.iqm_low, s.iqm_high)]
        # paired_difference leaves out the pairs of diverged agents itself, and needs 2 pairs left
        paired = str(paired_difference(evaluation, final)) if on_final.n - on_final.n_diverged >= 2 else "—"
        lines.append(f"| {label} | {len(found)} | " + " | ".join(cells) + f" | {paired} |")
    lines += ["", f"Episode i of every agent is reset with env seed {first_seed} + i; the training seeds are the "
                  "agents' own."]
    return "\n".join(lines) + "\n", rows

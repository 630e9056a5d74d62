"""`ermrl analyze evaluate`: saved agents' returns over fresh episodes, deterministic by default, beside their
training score; on real saved agents (the session's `saved` fixture) and real Gymnasium envs."""

import json

import numpy as np

from ermrl.agent_files import find_agents, read_agent
from ermrl.analysis.policy_eval import agent_returns
from ermrl.analysis.statistics import paired_difference, summarize

from cli_runs import ermrl


def test_cli_evaluates_every_agent_and_tables_it_beside_the_training_score(saved, tmp_path):
    """One row per run, over its 2 agents: the evaluation and the final recorded in the agent files, mean ± std
    and IQM, and their paired difference, all from the per-agent JSON; Pendulum's episodes are 200 steps of
    rewards in [−16.3, 0]."""
    out = tmp_path / "eval.md"
    r = ermrl("analyze", "evaluate", str(saved / "ermrl"), str(saved / "ppo"), "--episodes", "3", "--out", str(out))
    assert r.returncode == 0, r.stderr
    rows = json.loads(out.with_suffix(".json").read_text())
    assert [(row["run"].rsplit("/", 1)[1], row["seed"]) for row in rows] == [("ermrl", 0), ("ermrl", 1),
                                                                             ("ppo", 0), ("ppo", 1)]
    for row in rows:
        assert len(row["returns"]) == 3 and all(-16.3 * 200 < x < 0 for x in row["returns"])
        assert row["evaluation"] == np.mean(row["returns"])
        assert row["final"] == read_agent(row["agent"])[0]["fitness"]
    lines = out.read_text().splitlines()
    assert lines[0].startswith("| run | agents | evaluation (deterministic, 3 episodes each): mean ± std |")
    for line, run in zip(lines[2:4], ("ermrl", "ppo")):
        mine = [row for row in rows if row["run"].endswith(run)]
        evaluation, final = (np.array([row[k] for row in mine]) for k in ("evaluation", "final"))
        cells = line.strip("| ").split(" | ")
        s = summarize(evaluation)
        assert cells[1:4] == ["2", f"{evaluation.mean():.1f} ± {evaluation.std():.1f}",
                              f"{s.iqm:.1f} [{s.iqm_low:.1f}, {s.iqm_high:.1f}]"]
        assert cells[4] == f"{final.mean():.1f} ± {final.std():.1f}"
        assert cells[6] == str(paired_difference(evaluation, final))
    assert r.stdout == out.read_text() + f"wrote {out} and {out.with_suffix('.json')}\n"
    progress = r.stderr.splitlines()  # a line per agent, with the time left
    assert [line.split("] ")[0] for line in progress] == ["[1/4", "[2/4", "[3/4", "[4/4"]
    assert progress[0].startswith(f"[1/4] {rows[0]['agent']}: {rows[0]['evaluation']:.1f} over 3 episodes (")
    assert progress[-1].endswith(", ≈ 0 s left)")


def test_episodes_are_seeded_one_by_one_and_stochastic_actions_differ(saved):
    """Episode i is reset with env seed first_seed + i, so evaluations with shifted seeds share their episodes;
    the deterministic policy repeats itself exactly, the stochastic one draws other actions (Pendulum's Gaussian
    with std 1 at this budget), reproducibly."""
    agent = find_agents(saved / "ermrl")[0]
    _, five = agent_returns(agent, 5, first_seed=0)
    _, shifted = agent_returns(agent, 2, first_seed=3)
    np.testing.assert_array_equal(shifted, five[3:5])
    assert len(set(five.round(6))) == 5  # different starts, different returns
    _, stochastic = agent_returns(agent, 5, first_seed=0, deterministic=False)
    _, again = agent_returns(agent, 5, first_seed=0, deterministic=False)
    np.testing.assert_array_equal(stochastic, again)
    assert not np.allclose(stochastic, five)
    r = ermrl("analyze", "evaluate", str(agent), "--episodes", "2", "--stochastic")
    assert r.returncode == 0 and "evaluation (stochastic, 2 episodes each)" in r.stdout, r.stderr

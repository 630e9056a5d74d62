"""ermrl.analysis.rhythm: spectra and the rhythm score, on plain signals and on real reservoirs."""

import jax.numpy as jnp
import numpy as np
import pytest

from ermrl import reservoir
from ermrl.analysis.rhythm import (DRIFT_CYCLES, agent_rhythm, compare_runs, peak_cycles, plot_spectra, rhythm_score,
                                   spectrum, summed)
from ermrl.errors import ConfigError

from cli_runs import ermrl

T = 1024
STEPS = np.arange(T)


def test_spectrum_shapes_and_peak():
    freqs, power = spectrum(np.sin(2 * np.pi * STEPS / 25) + 3.0)
    assert freqs.shape == power.shape == (T // 2 + 1,)
    assert freqs[np.argmax(power)] == pytest.approx(1 / 25, abs=1 / T)
    assert power[0] < 1e-6 * power.max()  # the mean is removed
    freqs, _ = spectrum(np.sin(2 * np.pi * STEPS / 25), dt=0.02)
    assert freqs[-1] == pytest.approx(0.5 / 0.02)
    assert summed(np.ones((T, 7))).shape == (T,) and np.all(summed(np.ones((T, 7))) == 7)


def test_sine_scores_near_one_and_white_noise_near_zero():
    for period in (10, 25, 33.3, 64.7):  # on a bin and between bins
        assert rhythm_score(np.sin(2 * np.pi * STEPS / period + 0.3)) > 0.99  # measured >= 0.9996
    rng = np.random.default_rng(0)
    noise = [rhythm_score(rng.standard_normal(T)) for _ in range(10)]
    assert max(noise) < 0.1  # measured 0.016..0.037; the band holds 5 of 512 bins
    assert rhythm_score(np.full(T, 2.0)) == 0.0


def test_a_slow_drift_scores_like_a_rhythm_and_its_peak_shows_it():
    """A ramp, or one slow swing over the window, puts its power in the lowest bins and scores ~1 like a sine;
    peak_cycles tells them apart: 7 cycles for a 7-cycle sine, below DRIFT_CYCLES for the drifts."""
    sine = np.sin(2 * np.pi * 7 * STEPS / T + 0.3)
    ramp, swing = STEPS / T, np.sin(np.pi * STEPS / T)
    assert peak_cycles(sine) == 7 and peak_cycles(np.full(T, 2.0)) == 0
    for drift in (ramp, swing):
        assert rhythm_score(drift) > 0.95 and 0 < peak_cycles(drift) < DRIFT_CYCLES
    assert peak_cycles(swing + 0.1 * sine) == 1 and peak_cycles(0.2 * swing + sine) == 7  # whichever dominates


def test_a_reservoir_driven_by_a_sine_is_more_rhythmic_than_one_driven_by_noise():
    unit = reservoir.generate(reservoir.ReservoirSpec(units=100), 0, 1)
    weights = reservoir.scale(unit, 0.95, 1.0)
    sine = jnp.asarray(np.sin(2 * np.pi * STEPS / 25)[:, None], jnp.float32)
    noise = jnp.asarray(np.random.default_rng(0).standard_normal((T, 1)), jnp.float32)
    driven_by_sine = np.asarray(reservoir.run(weights, 0.5, sine))
    driven_by_noise = np.asarray(reservoir.run(weights, 0.5, noise))
    assert driven_by_sine.shape == (T, 100)
    rhythmic, noisy = rhythm_score(summed(driven_by_sine)), rhythm_score(summed(driven_by_noise))
    # Measured with reservoir seeds 0..3: 0.988..0.998 vs 0.06..0.13 (the reservoir low-passes the noise).
    assert rhythmic > 0.9 and noisy < 0.3 and rhythmic - noisy > 0.6


def test_plot_and_errors(tmp_path):
    signals = {"sine": np.sin(2 * np.pi * STEPS / 25), "noise": np.random.default_rng(1).standard_normal(T)}
    out = plot_spectra(signals, tmp_path / "spectra.png", dt=0.02)
    assert out.read_bytes()[:4] == b"\x89PNG"
    with pytest.raises(ConfigError, match="reduce a \\(T, D\\) trace with summed"):
        rhythm_score(np.ones((T, 2)))
    with pytest.raises(ConfigError, match="traces must be \\(T, D\\)"):
        summed(np.ones(T))
    with pytest.raises(ConfigError, match="dt must be > 0"):
        spectrum(np.ones(T), dt=0)
    with pytest.raises(ConfigError, match="at least one signal"):
        plot_spectra({}, tmp_path / "empty.png")


def test_cli_context_and_fft_on_saved_agents(saved, tmp_path):
    """`ermrl analyze context` and `ermrl analyze fft` on real saved agents (ER-MRL and PPO, 2 seeds each): the
    fft table has one row per run with both agents; for PPO the policy input is the observation, so its two
    rhythm scores are equal; the per-agent JSON and the figures are written."""
    import json

    r = ermrl("analyze", "context", str(saved / "ermrl"))
    assert r.returncode == 0, r.stderr
    assert (saved / "ermrl" / "context.png").read_bytes().startswith(b"\x89PNG")
    fig = tmp_path / "fft.png"
    r = ermrl("analyze", "fft", str(saved / "ermrl"), str(saved / "ppo"), "--out", str(fig))
    assert r.returncode == 0, r.stderr
    lines = fig.with_suffix(".md").read_text().splitlines()
    assert [line.split(" | ")[1] for line in lines[2:]] == ["2", "2"]
    ppo = lines[3].rstrip(" |").split(" | ")
    assert ppo[0].endswith("ppo") and ppo[3] == ppo[4] and ppo[5] == "—"  # no context to compare
    assert ppo[6].split(" / ")[0] == ppo[6].split(" / ")[1]  # the same signal: the same drifts
    rows = json.loads(fig.with_suffix(".json").read_text())
    assert len(rows) == 4 and all(0 <= row["rhythm_input"] <= 1 and row["steps"] == 200 for row in rows)
    # the ER-MRL row's paired input − observation, over its 2 agents, from the per-agent scores
    from ermrl.analysis.statistics import paired_difference

    mine = [row for row in rows if row["run"].endswith("ermrl")]
    paired = paired_difference([row["rhythm_input"] for row in mine], [row["rhythm_observation"] for row in mine])
    assert lines[2].rstrip(" |").split(" | ")[5] == str(paired) and paired.n == 2
    drifts = sum(0 < row["peak_cycles_observation"] < DRIFT_CYCLES for row in mine)
    assert lines[2].rstrip(" |").split(" | ")[6] == f"{drifts} / {sum(0 < r['peak_cycles_input'] < DRIFT_CYCLES for r in mine)}"
    assert fig.read_bytes().startswith(b"\x89PNG")
    for args, message in [
        (["fft", str(tmp_path / "nothing"), "--out", str(fig)],
         f"{tmp_path / 'nothing'} does not exist; give a run folder or a saved agent file (.npz)"),
        (["context", str(saved / "ppo")], f"{saved / 'ppo' / 'agents' / 'seed0.npz'} is a plain PPO agent: it "
                                              "has no reservoir to plot; give an ER-MRL agent"),
    ]:
        r = ermrl("analyze", *args)
        assert r.returncode == 2 and r.stderr == f"ermrl analyze: error: {message}\n", r.stderr
    empty = tmp_path / "empty"
    empty.mkdir()
    r = ermrl("analyze", "fft", str(empty), "--out", str(fig))
    assert r.stderr == f"ermrl analyze: error: {empty} holds no saved agent; train with --save-agents (the default) first\n"


def test_agents_whose_episode_is_too_short_are_left_out_and_named(saved, tmp_path):
    """A test phase's agent may fall at once (an Ant after 1M steps ended its episode in 7): that agent is left
    out of the rhythm table and named under it, and the others are scored; a run whose every agent is short is a
    one-line error. Real agents: Pendulum's episodes last 200 steps, an early CartPoleNoVel agent's far fewer."""
    from ermrl.agent_files import find_agents

    pendulum, cartpole = (find_agents(saved / name)[0] for name in ("ermrl", "cartpole"))
    cartpole_steps = agent_rhythm(cartpole)["steps"]
    assert cartpole_steps < 100
    table, rows = compare_runs({"mixed": [pendulum, cartpole]}, tmp_path / "fft.png", min_steps=100)
    assert [row["agent"] for row in rows] == [str(pendulum)]
    assert table.splitlines()[2].startswith("| mixed | 1 | 200 | ") and table.splitlines()[2].endswith(" | 1 |")
    assert table.splitlines()[-1] == (f"Left out: {cartpole}: the episode lasted {cartpole_steps} steps, too few for a "
                                      "spectrum.")
    r = ermrl("analyze", "fft", str(saved / "ermrl"), "--max-steps", "5", "--out", str(tmp_path / "f.png"))
    assert (r.returncode, r.stderr) == (2, f"ermrl analyze: error: every agent of {saved / 'ermrl'} ended "
                                           f"its episode in under 8 steps, too few for a spectrum (first: {pendulum}: "
                                           "the episode lasted 5 steps, too few for a spectrum); use agents that "
                                           "survive longer or a larger --max-steps\n")

"""How rhythmic a signal is (paper, appendix "Results analysis": the reservoir as a central pattern generator).

The appendix compares the spectrum of the summed observation with that of the summed context (the reservoir
states): the context's power gathers in a narrow band, the observation's does not. :func:`summed` reduces a
(T, D) trace to (T,), :func:`spectrum` gives its power spectrum and :func:`rhythm_score` the fraction of power
in the band around the dominant peak.

The rhythm score, precisely: take the power spectrum P of the mean-removed, Hann-windowed signal (rfft bins
0..T//2), drop the DC bin 0, find the peak bin p = argmax P[1:], and return

    sum(P[b] for b in 1..T//2 with |b − p| <= half_width) / sum(P[1:])

a value in [0, 1]. The Hann window keeps a sine's power inside its main lobe (±2 bins) wherever its frequency
falls between bins: a pure sine scores ~1 with the default half_width 2. White noise spreads its power evenly,
so it scores about (2·half_width + 1) / (T/2), a little more since the peak is the largest of its bins. A constant
signal (no power off DC) scores 0.

A slow drift also scores ~1: a signal that wanders once over the window (a swimmer slowly turning, a ramp) puts
its power in the lowest bins, and that is one narrow band, but not a gait. :func:`peak_cycles` gives the peak's
bin, i.e. how many times the dominant component repeats in the window; the tables flag a peak below
``DRIFT_CYCLES`` as a drift, so that such a score is not read as a rhythm. (Cutting those bins off does not fix
the score: a large drift leaks into the next bins through the window's main lobe, so the result would hinge on
the cut.)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ermrl.errors import ConfigError

HALF_WIDTH = 2
"""Default half width, in bins, of the band around the peak that :func:`rhythm_score` counts."""
DRIFT_CYCLES = 3
"""A dominant peak repeating fewer times than this in the window is flagged as a drift, not a rhythm."""


def _as_signal(signal, name: str = "signal") -> np.ndarray:
    signal = np.asarray(signal, np.float64)
    if signal.ndim != 1 or signal.shape[0] < 4:
        raise ConfigError(f"{name} must be 1-D with at least 4 samples, got shape {signal.shape}; "
                          "reduce a (T, D) trace with summed() first")
    if not np.all(np.isfinite(signal)):
        raise ConfigError(f"{name} has NaN or inf values; drop them before computing a spectrum")
    return signal


def spectrum(signal: np.ndarray, dt: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Power spectrum of a (T,) signal sampled every ``dt``: numpy.fft.rfft of the mean-removed signal times a
    Hann window. Returns (freqs (F,), power (F,)) with F = T//2 + 1; freqs in cycles per unit of ``dt``,
    power |rfft|² (bin 0 is DC, ~0 after the mean removal)."""
    signal = _as_signal(signal)
    if not dt > 0:
        raise ConfigError(f"dt must be > 0 (the sampling interval), got {dt}")
    x = (signal - signal.mean()) * np.hanning(len(signal))
    return np.fft.rfftfreq(len(signal), dt), np.abs(np.fft.rfft(x)) ** 2


def rhythm_score(signal: np.ndarray, half_width: int = HALF_WIDTH) -> float:
    """Fraction, in [0, 1], of a (T,) signal's non-DC power within ``half_width`` bins of its dominant peak
    (see the module docstring). 1: a single rhythm; ~(2·half_width + 1)/(T/2): white noise."""
    if half_width < 0:
        raise ConfigError(f"half_width must be >= 0 bins, got {half_width}")
    _, power = spectrum(signal)
    power = power[1:]
    total = power.sum()
    if total <= 0.0:
        return 0.0
    peak = int(np.argmax(power))
    band = power[max(0, peak - half_width): peak + half_width + 1]
    return float(min(1.0, band.sum() / total))


def peak_cycles(signal: np.ndarray) -> int:
    """The dominant non-DC bin of a (T,) signal's spectrum: how many cycles of its strongest component fit in the
    T samples (0 for a constant signal). Below ``DRIFT_CYCLES`` the peak is a drift, not a rhythm."""
    _, power = spectrum(signal)
    return int(np.argmax(power[1:]) + 1) if power[1:].sum() > 0.0 else 0


def summed(traces: np.ndarray) -> np.ndarray:
    """Sum over dimensions of a (T, D) trace (observations or reservoir states) -> (T,)."""
    traces = np.asarray(traces)
    if traces.ndim != 2:
        raise ConfigError(f"traces must be (T, D), got shape {traces.shape}")
    return traces.sum(axis=1)


def plot_spectra(named_signals: dict[str, np.ndarray], path: Path | str, dt: float = 1.0,
                 half_width: int = HALF_WIDTH) -> Path:
    """Plots each (T,) signal's power spectrum (normalized to unit non-DC power, DC left out, log scale), its
    rhythm score in the legend. Writes ``path`` as a PNG and returns it."""
    from matplotlib.figure import Figure

    from ermrl.storage import save_figure

    if not named_signals:
        raise ConfigError("plot_spectra needs at least one signal, e.g. {'summed context': summed(states)}")
    fig = Figure(figsize=(7, 4))
    ax = fig.subplots()
    for name, signal in named_signals.items():
        freqs, power = spectrum(signal, dt)
        total = power[1:].sum()
        ax.semilogy(freqs[1:], power[1:] / total if total > 0 else power[1:],
                    label=f"{name} (rhythm {rhythm_score(signal, half_width):.2f})")
    ax.set_xlabel("frequency (cycles per step)" if dt == 1.0 else f"frequency (cycles per unit, dt={dt:g})")
    ax.set_ylabel("power (fraction of non-DC)")
    ax.grid(alpha=0.3)
    ax.legend()
    return save_figure(fig, Path(path).with_suffix(".png"))


MIN_STEPS = 8
"""The shortest episode whose spectrum is computed: below it an FFT has too few frequencies to place a peak."""


class ShortEpisode(ConfigError):
    """A saved agent's episode ended before ``MIN_STEPS`` steps (e.g. an Ant that falls at once)."""


def agent_rhythm(agent_file: Path | str, seed: int = 0, max_steps: int | None = None,
                 min_steps: int = MIN_STEPS) -> dict:
    """One deterministic episode of a saved agent (reset with ``seed``): the rhythm score of its summed
    observation and of its summed policy input (the context c_t; for plain PPO, the observation itself), and both
    summed signals (T,) for plotting. Raises :class:`ShortEpisode` when the episode lasts under ``min_steps``."""
    from ermrl.analysis.context import record_episode
    from ermrl.saved_agent import load_agent

    agent = load_agent(agent_file)
    env = agent.make_env()
    try:
        obs, context, rewards = record_episode(agent, env, seed, max_steps)
    finally:
        env.close()
    if len(obs) < min_steps:
        raise ShortEpisode(f"{agent_file}: the episode lasted {len(obs)} steps, too few for a spectrum; "
                           "use an agent that survives longer or a larger `max_steps`", owner=agent_rhythm)
    o, c = summed(obs), summed(context)
    return {"agent": str(agent_file), "env_id": agent.env_id, "reservoirs": agent.config.reservoirs,
            "steps": len(obs), "return": float(rewards.sum()), "rhythm_observation": rhythm_score(o),
            "rhythm_input": rhythm_score(c), "peak_cycles_observation": peak_cycles(o), "peak_cycles_input":
            peak_cycles(c), "summed_observation": o, "summed_input": c}


def compare_runs(sources: dict[str, list[Path]], path: Path | str, seed: int = 0,
                 max_steps: int | None = None, min_steps: int = MIN_STEPS) -> tuple[str, list[dict]]:
    """Rhythm of every saved agent of each named source (label -> agent files, e.g. a test phase's ER-MRL and
    PPO agents). Returns a Markdown table (one row per source: the mean ± std over its agents of the rhythm of the
    summed observation and of the summed policy input, and for agents with reservoirs the paired difference input −
    observation over its agents, the paper's "the context is more rhythmic than the observation"; and how many
    agents' peaks are drifts, observation / input) and the per-agent rows; plots the spectra of the first agent of
    each source at ``path``. An agent whose episode lasts under ``min_steps`` is left out and named below the
    table (a source left with none is an error)."""
    from ermrl.analysis.statistics import paired_difference

    rows, lines = [], ["| run | agents | episode steps | rhythm, summed observation | rhythm, summed policy input "
                       f"| input − observation, paired [95% CI] | drifts (peak < {DRIFT_CYCLES} cycles), obs / input "
                       f"| left out (episode < {min_steps} steps) |",
                       "|---|---:|---:|---|---|---|---|---:|"]
    signals, left_out_all = {}, []
    for label, files in sources.items():
        if not files:
            raise ConfigError(f"{label} holds no saved agent; train with `save_agents` (the default) first")
        found, left_out = [], []
        for f in files:
            try:
                found.append({**agent_rhythm(f, seed, max_steps, min_steps), "run": label})
            except ShortEpisode as error:
                left_out.append(str(error).split(";")[0])
        if not found:
            raise ConfigError(f"every agent of {label} ended its episode in under {min_steps} steps, too few for a "
                              f"spectrum (first: {left_out[0]}); use agents that survive longer or a larger "
                              "`max_steps`", owner=compare_runs)
        left_out_all += left_out
        rows += found
        obs, inp = (np.array([r[k] for r in found]) for k in ("rhythm_observation", "rhythm_input"))
        steps = np.mean([r["steps"] for r in found])
        paired = str(paired_difference(inp, obs)) if found[0]["reservoirs"] and len(found) >= 2 else "—"
        lines.append(f"| {label} | {len(found)} | {steps:.0f} | {obs.mean():.3f} ± {obs.std():.3f} | "
                     f"{inp.mean():.3f} ± {inp.std():.3f} | {paired} | {_drifts(found, 'observation')} / "
                     f"{_drifts(found, 'input')} | {len(left_out)} |")
        short = Path(label).name or label
        signals[f"{short}: summed observation"] = found[0]["summed_observation"]
        if found[0]["reservoirs"]:
            signals[f"{short}: summed context"] = found[0]["summed_input"]
    plot_spectra(signals, path)
    lines += [""] * bool(left_out_all) + [f"Left out: {reason}." for reason in left_out_all]
    return "\n".join(lines) + "\n", [{k: v for k, v in r.items() if not k.startswith("summed")} for r in rows]


def _drifts(rows: list[dict], signal: str) -> int:
    """How many of ``rows`` (agent_rhythm's) have their ``signal``'s peak below DRIFT_CYCLES (a constant's, 0,
    is no drift)."""
    return sum(0 < r[f"peak_cycles_{signal}"] < DRIFT_CYCLES for r in rows)

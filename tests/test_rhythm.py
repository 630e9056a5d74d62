"""ermrl.analysis.rhythm: spectra and the rhythm score, on plain signals and on real reservoirs."""

import jax.numpy as jnp
import numpy as np
import pytest

from ermrl import reservoir
from ermrl.analysis.rhythm import plot_spectra, rhythm_score, spectrum, summed
from ermrl.errors import ConfigError

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

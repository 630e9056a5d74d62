import jax.numpy as jnp
import numpy as np
import pytest

from ermrl import reservoir
from ermrl.reservoir import ReservoirSpec


def scaled(spec, seed, input_dim, sr, iss):
    return reservoir.scale(reservoir.generate(spec, seed, input_dim), sr, iss)


def test_matches_reservoirpy_trajectory_given_the_same_weights():
    rpy_nodes = pytest.importorskip("reservoirpy.nodes")
    spec = ReservoirSpec(units=100)
    w = scaled(spec, seed=3, input_dim=5, sr=0.95, iss=1.3)
    inputs = np.random.default_rng(0).normal(size=(200, 5)).astype(np.float32)
    lr = 0.37
    ref = rpy_nodes.Reservoir(W=np.asarray(w.W, np.float64), Win=np.asarray(w.Win, np.float64),
                              bias=np.asarray(w.bias, np.float64), lr=lr)
    expected = ref.run(inputs.astype(np.float64))
    ours = np.asarray(reservoir.run(w, jnp.float32(lr), jnp.asarray(inputs)))
    assert ours.shape == (200, 100)
    np.testing.assert_allclose(ours, expected, atol=1e-5)


@pytest.mark.parametrize("sr", [1e-4, 0.95, 3.0, 100.0])
def test_spectral_radius_equals_sr(sr):
    w = scaled(ReservoirSpec(), seed=1, input_dim=4, sr=sr, iss=1.0)
    radius = np.max(np.abs(np.linalg.eigvals(np.asarray(w.W, np.float64))))
    assert radius == pytest.approx(sr, rel=1e-6)


def test_density_and_value_sets():
    spec = ReservoirSpec(units=200)
    iss = 2.5
    w = scaled(spec, seed=7, input_dim=10, sr=0.9, iss=iss)
    W, Win, bias = map(np.asarray, w)
    assert np.count_nonzero(W) / W.size == pytest.approx(0.1, abs=0.005)
    assert np.count_nonzero(Win) / Win.size == pytest.approx(0.1, abs=0.01)
    assert set(np.unique(Win)) == {-iss, 0.0, iss}
    assert set(np.unique(bias)) == {-1.0, 0.0, 1.0}
    assert np.count_nonzero(bias) == 20  # ±1 on 10% of the units (ReservoirPy 0.3)
    nonzero = W[W != 0] / 0.9
    assert abs(nonzero.mean()) < 0.2 * nonzero.std()  # centred normal weights


def test_no_bias_option_and_seeds():
    spec = ReservoirSpec(bias="none")
    a, b, c = (reservoir.generate(spec, s, 3) for s in (0, 0, 1))
    assert not np.any(a.bias)
    np.testing.assert_array_equal(a.W, b.W)
    assert not np.array_equal(a.W, c.W)


def test_update_rule_and_bounded_states():
    w = scaled(ReservoirSpec(units=20), seed=0, input_dim=2, sr=100.0, iss=10.0)
    x = jnp.full((20,), 0.5)
    u = jnp.array([1.0, -2.0])
    lr = 0.25
    expected = (1 - lr) * x + lr * jnp.tanh(w.W @ x + w.Win @ u + w.bias)
    np.testing.assert_allclose(reservoir.step(w, lr, x, u), expected, rtol=1e-6)
    states = reservoir.run(w, 1.0, jnp.ones((50, 2)) * 100)
    assert np.all(np.abs(np.asarray(states)) <= 1.0)


@pytest.mark.parametrize("bad", [dict(units=0), dict(rc_connectivity=0.0), dict(input_connectivity=1.5), dict(bias="x")])
def test_bad_specs_are_rejected(bad):
    with pytest.raises(ValueError):
        ReservoirSpec(**bad)

"""Reservoirs (echo state networks) with ReservoirPy semantics.

A reservoir is generated from its hyperparameters Φ = (sr, lr, iss) plus ``units`` (paper §2.3, App. A.1.2):

- ``W``   (units, units): sparse N(0, 1) weights, ``rc_connectivity`` of them non-zero, rescaled so that
  max|eig(W)| = sr;
- ``Win`` (units, input_dim): sparse Bernoulli ±1 weights, ``input_connectivity`` of them non-zero, times iss;
- ``bias`` (units,): ReservoirPy 0.3 (the paper's era) draws ±1 on ``input_connectivity`` of the units,
  times ``bias_scaling``; ReservoirPy 0.4 has no bias (``bias="none"``);
- update: x ← (1 − lr)·x + lr·tanh(W x + Win u + b).

Generation is split in two so that Φ can be traced through JAX: :func:`generate` draws the *unit* weights
(spectral radius 1, input scaling 1) from a seed on the host with NumPy, and :func:`scale` applies Φ inside
the jitted program. Since eig(sr·W₁) = sr·eig(W₁), this is exactly ReservoirPy's rescaling.
"""

from __future__ import annotations

import dataclasses
from typing import Literal, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ermrl.errors import ConfigError


@dataclasses.dataclass(frozen=True)
class ReservoirSpec:
    """The static part of a reservoir: what sets array shapes and sparsity, not Φ."""

    units: int = 100
    """Number of neurons N (the paper uses 100)."""
    rc_connectivity: float = 0.1
    """Fraction of non-zero recurrent weights in W (ReservoirPy default)."""
    input_connectivity: float = 0.1
    """Fraction of non-zero input weights in Win, and of units with a bias (ReservoirPy default)."""
    bias: Literal["bernoulli", "none"] = "bernoulli"
    """"bernoulli": ±1 on ``input_connectivity`` of the units (ReservoirPy 0.3, the paper); "none": 0.4."""
    bias_scaling: float = 1.0
    """Scale of the bias (ReservoirPy 0.3 default)."""

    def __post_init__(self):
        if self.units < 1:
            raise ConfigError(f"units must be >= 1, got {self.units}; a reservoir needs at least one neuron")
        for name in ("rc_connectivity", "input_connectivity"):
            value = getattr(self, name)
            if not 0.0 < value <= 1.0:
                raise ConfigError(f"{name} must be in (0, 1], got {value}; it is a fraction of the weights "
                                  "(ReservoirPy's default: 0.1)")
        if self.bias not in ("bernoulli", "none"):
            raise ConfigError(f"bias must be 'bernoulli' or 'none', got {self.bias!r}")
        if not 0.0 <= self.bias_scaling < float("inf"):
            raise ConfigError(f"bias_scaling must be a finite number >= 0, got {self.bias_scaling}")


class ReservoirWeights(NamedTuple):
    """Weights of one reservoir. Unit weights from :func:`generate`, or scaled ones from :func:`scale`."""

    W: jax.Array
    """(units, units) recurrent weights."""
    Win: jax.Array
    """(units, input_dim) input weights."""
    bias: jax.Array
    """(units,) bias."""


def _sparse(rng: np.random.Generator, shape: tuple[int, int], density: float, values) -> np.ndarray:
    """A dense array with exactly round(density·size) non-zeros at uniformly drawn positions."""
    size = shape[0] * shape[1]
    nnz = max(1, int(round(density * size)))
    out = np.zeros(size)
    positions = rng.choice(size, size=nnz, replace=False)
    out[positions] = values(nnz)
    return out.reshape(shape)


def generate(spec: ReservoirSpec, seed: int, input_dim: int) -> ReservoirWeights:
    """Draws unit weights (max|eig(W)| = 1, input scaling 1) for one reservoir from ``seed``.

    Returns float32 NumPy arrays: W (units, units), Win (units, input_dim), bias (units,).
    """
    rng = np.random.default_rng(seed)
    n = spec.units
    W = _sparse(rng, (n, n), spec.rc_connectivity, rng.standard_normal)
    radius = np.max(np.abs(np.linalg.eigvals(W)))
    if radius < 1e-12:  # a nilpotent draw (only possible for tiny, very sparse W): redraw deterministically
        return generate(spec, seed + 1_000_003, input_dim)
    W = W / radius
    Win = _sparse(rng, (n, input_dim), spec.input_connectivity, lambda k: rng.choice([-1.0, 1.0], size=k))
    if spec.bias == "bernoulli":
        bias = _sparse(rng, (n, 1), spec.input_connectivity, lambda k: rng.choice([-1.0, 1.0], size=k))[:, 0]
        bias = bias * spec.bias_scaling
    else:
        bias = np.zeros(n)
    return ReservoirWeights(W.astype(np.float32), Win.astype(np.float32), bias.astype(np.float32))


def scale(unit: ReservoirWeights, sr: jax.Array, iss: jax.Array) -> ReservoirWeights:
    """Applies the spectral radius ``sr`` and input scaling ``iss`` (scalars, may be traced) to unit weights."""
    return ReservoirWeights(unit.W * sr, unit.Win * iss, unit.bias)


def step(weights: ReservoirWeights, lr: jax.Array, x: jax.Array, u: jax.Array) -> jax.Array:
    """One leaky-integrator update. x: (units,) state, u: (input_dim,) input, lr: scalar. Returns (units,)."""
    pre = weights.W @ x + weights.Win @ u + weights.bias
    return (1.0 - lr) * x + lr * jnp.tanh(pre)


def first_step(weights: ReservoirWeights, lr: jax.Array, u: jax.Array) -> jax.Array:
    """:func:`step` from the zero state, without the (then useless) W x product. Returns (units,)."""
    return lr * jnp.tanh(weights.Win @ u + weights.bias)


def run(weights: ReservoirWeights, lr: jax.Array, inputs: jax.Array, x0: jax.Array | None = None) -> jax.Array:
    """Runs a reservoir over a sequence. inputs: (T, input_dim). Returns the states (T, units)."""
    x = jnp.zeros(weights.W.shape[0], inputs.dtype) if x0 is None else x0

    def body(x, u):
        x = step(weights, lr, x, u)
        return x, x

    _, states = jax.lax.scan(body, x, inputs)
    return states

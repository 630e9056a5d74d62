"""A sum whose rounding does not depend on how many agents are stepped together.

XLA:CPU vectorizes a reduction (``jnp.sum``) differently depending on the shape around it, so under ``vmap`` the
same agent's sum over its 6 action dimensions can round differently in a population of 3 agents per device than
in one of 8 (measured: sums over 6 or 17 floats differ in the last bit between population sizes; sums over 64
did not). One bit is enough for MuJoCo's chaotic dynamics to give another episode a few updates later. The
rollout is ``vmap``-ed over a device's agents, so its Gaussian log-probabilities and entropies sum their action
dimensions with :func:`tree_sum`: a fixed pairwise order made of slices and elementwise additions only, which XLA
computes the same way for any batch around them. (The update runs one agent at a time instead:
:mod:`ermrl.training.programs`.) With both, an agent trains the same alone and inside any population, the
condition for training several studies as one population.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def tree_sum(x: jax.Array, axis: int = -1) -> jax.Array:
    """Sum of ``x`` over ``axis`` in a fixed pairwise order: the axis is padded with zeros to a power of two and
    halved, ``x[:half] + x[half:]``, until one entry is left. Shapes: (..., n, ...) -> (..., ...)."""
    x = jnp.moveaxis(x, axis, -1)
    n = x.shape[-1]
    if n == 0:
        return jnp.zeros(x.shape[:-1], x.dtype)
    size = 1 << (n - 1).bit_length()
    if size != n:
        x = jnp.concatenate([x, jnp.zeros(x.shape[:-1] + (size - n,), x.dtype)], axis=-1)
    while x.shape[-1] > 1:
        half = x.shape[-1] // 2
        x = x[..., :half] + x[..., half:]
    return x[..., 0]

"""The recurrent product W x of a population of large reservoirs: dense (what ermrl.reservoir.step does) against a
padded-row sparse form (ELL: each row's non-zeros and their column indices, padded to the longest row).

W has ReservoirPy's 10% non-zeros, so a sparse form reads ≈ 4× fewer bytes at 1000 units (values and int32
indices of ≈ 138 entries per row, against 1000 floats); the question is whether XLA's gather on the CPU turns
that into speed. Prints the median milliseconds per step of ``--steps`` steps (tanh(W x), scanned), 5 runs each.

    .venv/bin/python benchmarks/sparse_reservoir_product.py --agents 18 --units 1000
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np


def padded_rows(W: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """W (agents, units, units) -> (indices, values), each (agents, units, k): k the most non-zeros in a row."""
    k = int((W != 0).sum(-1).max())
    idx = np.zeros(W.shape[:2] + (k,), np.int32)
    val = np.zeros(W.shape[:2] + (k,), np.float32)
    for a in range(W.shape[0]):
        for i in range(W.shape[1]):
            (nz,) = np.nonzero(W[a, i])
            idx[a, i, :len(nz)], val[a, i, :len(nz)] = nz, W[a, i, nz]
    return idx, val


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--agents", type=int, default=18)
    parser.add_argument("--units", type=int, default=1000)
    parser.add_argument("--steps", type=int, default=200)
    args = parser.parse_args(argv)

    import jax
    import jax.numpy as jnp

    from ermrl.reservoir import ReservoirSpec, generate

    W = np.stack([generate(ReservoirSpec(units=args.units), seed, 4).W for seed in range(args.agents)])
    idx, val = padded_rows(W)
    x0 = np.random.default_rng(0).standard_normal((args.agents, args.units)).astype(np.float32) * 0.1

    def dense(W, x):
        return jax.lax.scan(lambda x, _: (jnp.tanh(jnp.einsum("aij,aj->ai", W, x)), None), x, None, args.steps)[0]

    def sparse(idx, val, x):
        def body(x, _):
            return jnp.tanh((val * jax.vmap(lambda xa, ia: xa[ia])(x, idx)).sum(-1)), None
        return jax.lax.scan(body, x, None, args.steps)[0]

    runs = {"dense": (jax.jit(dense), (W, x0)), "padded rows": (jax.jit(sparse), (idx, val, x0))}
    outs = {name: np.asarray(f(*map(jnp.asarray, a))) for name, (f, a) in runs.items()}
    print(f"{args.agents} agents × {args.units} units, {idx.shape[-1]} entries per padded row; "
          f"max |dense − sparse| after {args.steps} steps: {np.abs(outs['dense'] - outs['padded rows']).max():.2e}")
    for name, (f, a) in runs.items():
        a = tuple(map(jnp.asarray, a))
        times = []
        for _ in range(5):
            t = time.perf_counter()
            f(*a).block_until_ready()
            times.append(time.perf_counter() - t)
        print(f"{name}: {statistics.median(times) / args.steps * 1e3:.2f} ms per step")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

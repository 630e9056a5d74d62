import os
import tempfile

# One persistent JAX compilation cache for the whole run, inherited by the CLI subprocesses: the many tests that
# compile the same program (CartPoleNoVel at a CI budget, ...) compile it once. Set before JAX initializes.
os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", tempfile.mkdtemp(prefix="ermrl-jax-cache-"))

import ermrl  # noqa: E402,F401  (sets up one JAX device per CPU core before jax initializes)

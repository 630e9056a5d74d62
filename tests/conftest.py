import ermrl  # noqa: F401  (sets up one JAX device per CPU core before jax initializes)

"""ermrl: Evolving Reservoirs for Meta Reinforcement Learning, with a whole population trained as one JAX program."""

import os as _os

import jax as _jax

# Expose every CPU core as a JAX device so that a population can be sharded over them. This only takes
# effect before jax initializes its backends; ERMRL_CPU_DEVICES overrides the count.
try:
    _jax.config.update("jax_num_cpu_devices", int(_os.environ.get("ERMRL_CPU_DEVICES", _os.cpu_count() or 1)))
except RuntimeError:  # backends already initialized by the caller: keep their setting
    pass

__version__ = "0.1.0"


def __getattr__(name: str):
    """``ermrl.load_agent``, imported on first use so that ``import ermrl`` stays cheap."""
    if name == "load_agent":
        from ermrl.saved_agent import load_agent

        return load_agent
    raise AttributeError(f"module 'ermrl' has no attribute {name!r}")

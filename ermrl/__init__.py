"""ermrl: Evolving Reservoirs for Meta Reinforcement Learning, with a whole population trained as one JAX program."""

import os as _os

import jax as _jax



def _cpu_devices() -> tuple[int, str | None]:
    """(CPU devices to ask JAX for, the problem with ERMRL_CPU_DEVICES or None): one per core unless the variable
    sets a whole number >= 1. A bad value falls back to one per core; the CLI refuses it before any work."""
    cores = _os.cpu_count() or 1
    raw = _os.environ.get("ERMRL_CPU_DEVICES")
    if raw is None:
        return cores, None
    try:
        n = int(raw)
    except ValueError:
        n = 0
    if n < 1:
        return cores, (f"ERMRL_CPU_DEVICES must be a whole number >= 1 (the CPU devices a population is sharded "
                       f"over), got {raw!r}; unset it to use one per core ({cores})")
    return n, None


# Expose every CPU core as a JAX device so that a population can be sharded over them. This only takes
# effect before jax initializes its backends; ERMRL_CPU_DEVICES overrides the count.
_CPU_DEVICES, CPU_DEVICES_ERROR = _cpu_devices()
try:
    _jax.config.update("jax_num_cpu_devices", _CPU_DEVICES)
except RuntimeError:  # backends already initialized by the caller: keep their setting
    pass

__version__ = "0.1.0"


def __getattr__(name: str):
    """``ermrl.load_agent``, imported on first use so that ``import ermrl`` stays cheap."""
    if name == "load_agent":
        from ermrl.saved_agent import load_agent

        return load_agent
    raise AttributeError(f"module 'ermrl' has no attribute {name!r}")

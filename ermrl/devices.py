"""The CPU devices a population is sharded over: one JAX CPU device per core (``ERMRL_CPU_DEVICES`` overrides).

Asked for explicitly, by the CLI when it starts and by a :class:`~ermrl.training.trainer.Trainer` when it is
made, never at import: ``import ermrl`` (or ``ermrl.wrappers`` from an SB3 script) leaves JAX's settings alone.
JAX takes the count only before its backends start; a process that used JAX first keeps its own devices.
"""

from __future__ import annotations

import os

from ermrl.errors import ConfigError


def requested() -> tuple[int, str | None]:
    """(CPU devices to ask JAX for, the problem with ERMRL_CPU_DEVICES or None): one per core unless the variable
    sets a whole number in 1..:func:`max_devices`."""
    cores = os.cpu_count() or 1
    raw = os.environ.get("ERMRL_CPU_DEVICES")
    if raw is None:
        return cores, None
    try:
        n = int(raw)
    except ValueError:
        n = 0
    if n < 1:
        return cores, (f"ERMRL_CPU_DEVICES must be a whole number >= 1 (the CPU devices a population is sharded "
                       f"over), got {raw!r}; unset it to use one per core ({cores})")
    if n > max_devices(cores):
        return cores, (f"ERMRL_CPU_DEVICES must be at most {max_devices(cores)} (4 per core, at least 8: more devices "
                       f"than cores run no faster, and a population is padded to a multiple of them), got {raw!r}; "
                       f"unset it to use one per core ({cores})")
    return n, None


def max_devices(cores: int) -> int:
    """The most CPU devices ERMRL_CPU_DEVICES may ask for on ``cores`` cores: 4 per core, at least 8 (enough to
    try a GPU node's sharding on a laptop)."""
    return max(8, 4 * cores)


def setup() -> None:
    """Asks JAX for :func:`requested` CPU devices if its backends have not started (else keeps theirs). Raises
    ConfigError, naming the fix, for a bad ERMRL_CPU_DEVICES."""
    import jax

    n, problem = requested()
    if problem is not None:
        raise ConfigError(problem)
    try:
        jax.config.update("jax_num_cpu_devices", n)
    except RuntimeError:  # backends already initialized by the caller: keep their setting
        pass

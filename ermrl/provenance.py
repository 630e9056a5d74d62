"""The software and hardware a result was computed with: what decides its numbers.

A seed reproduces a run bit for bit only with the same versions of these packages, the same CPU instruction set
and XLA flags (XLA compiles for the host's widest vector unit, and wider vectors sum in another order), and the same
population size (see ``ermrl.experiments.evaluation``). Measured on Swimmer-v5, PPO, seeds 1000 and 1001, 10 agents,
mean return of the first two episodes (CHANGELOG.md, 2026-11-25):

- on an AVX-512 host, JAX 0.10.2, MuJoCo 4.0.0: 3.71577 and 2.15777;
- the same host limited to AVX2 (``XLA_FLAGS=--xla_cpu_max_isa=AVX2``): 3.78624 and 2.15777, the values of a run
  made on 2026-11-23, presumably on an AVX2 host;
- JAX 0.10.1: 3.65982 and 4.39429 (another random stream: another initial policy and other actions);
- MuJoCo 3.17.0: 3.71577 and 2.15775 (other rounding in the physics, which grows over training).

So every run folder, test phase, kept model, selection and study records :func:`software`, and a study resumed
(or a stored baseline reused) under other versions says so.
"""

from __future__ import annotations

import importlib.metadata
import os
import platform
from pathlib import Path

# The distributions whose version can change a result: random streams and arithmetic (jax, jaxlib, numpy), env
# dynamics (gymnasium, mujoco, box2d, gymnax), the update (optax, flax) and the search (optuna, cmaes).
PACKAGES = ("ermrl", "jax", "jaxlib", "numpy", "gymnasium", "mujoco", "box2d", "gymnax", "optax", "flax",
            "optuna", "cmaes")

# The widest x86 vector extension XLA may compile for, widest first, by its /proc/cpuinfo flag.
ISA_FLAGS = (("avx512f", "AVX-512"), ("avx2", "AVX2"), ("avx", "AVX"), ("sse4_2", "SSE4.2"))


def software() -> dict[str, str | None]:
    """{"python": "3.11.2", "cpu": "x86_64 AVX-512", "xla_flags": $XLA_FLAGS or None, package: version or None
    when it is not installed} for :data:`PACKAGES`. ermrl run from a source tree without being installed (as on a
    lent GPU machine, ``PYTHONPATH=.``) records its own ``__version__``."""
    versions: dict[str, str | None] = {"python": platform.python_version(), "cpu": cpu(),
                                       "xla_flags": os.environ.get("XLA_FLAGS") or None}
    for name in PACKAGES:
        try:
            versions[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            versions[name] = _source_version() if name == "ermrl" else None
    return versions


def _source_version() -> str:
    """ermrl's ``__version__``: this very package, imported from a source tree without distribution metadata."""
    from ermrl import __version__

    return __version__


def cpu(cpuinfo: Path = Path("/proc/cpuinfo")) -> str:
    """The machine and, on Linux, its widest vector extension: "x86_64 AVX-512", "x86_64 AVX2", "aarch64"."""
    machine = platform.machine() or "unknown"
    try:
        text = cpuinfo.read_text()
    except OSError:
        return machine
    flags = next((line.split(":", 1)[1].split() for line in text.splitlines() if line.startswith("flags")), [])
    return next((f"{machine} {name}" for flag, name in ISA_FLAGS if flag in flags), machine)


def differences(recorded: dict, current: dict | None = None) -> list[str]:
    """``"jax 0.10.2 → 0.10.1"`` for each package whose recorded version differs from the current one (a
    package that one side does not record is left out: older records have fewer)."""
    current = software() if current is None else current
    return [f"{name} {recorded[name]} → {current[name]}" for name in recorded
            if name in current and recorded[name] != current[name]]

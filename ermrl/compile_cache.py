"""JAX's persistent compilation cache for ermrl's commands: a program compiled once (a population's training
iteration: seconds to tens of seconds) is read back from disk by the next process of the same shape.

The CLI turns it on (:func:`enable`) in ``$ERMRL_COMPILE_CACHE``, else in the folder JAX was given
(``JAX_COMPILATION_CACHE_DIR``), else ``$XDG_CACHE_HOME/ermrl/jax``, else
``~/.cache/ermrl/jax``, at most :data:`MAX_BYTES`; ``ERMRL_COMPILE_CACHE=off`` turns it off. A folder that cannot be made or written leaves
it off (a run never fails for its cache), and JAX itself only warns on an entry it cannot read, then compiles.
Once the folder exists, a command writes nothing there until it compiles (a refused command writes nothing).
Library users call :func:`enable` themselves, or set JAX's own options.
"""

from __future__ import annotations

import os
from pathlib import Path

VARIABLE = "ERMRL_COMPILE_CACHE"
OFF = ("off", "0", "false", "no", "none", "")
MAX_BYTES = 2 * 2**30
"""The cache's size bound: past it, the least recently used programs are removed. Bounded, JAX reads and writes
its entries under a file lock (the ``filelock`` package), so that processes sharing the folder never read a
half-written one."""


def folder() -> Path | None:
    """Where the cache lives, from the environment (see the module's docstring); None when it is turned off."""
    raw = os.environ.get(VARIABLE)
    if raw is not None:
        return None if raw.strip().lower() in OFF else Path(raw).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "ermrl" / "jax"


def _writable(path: Path) -> bool:
    """Whether JAX can write its entries in ``path``: an existing folder is asked (its permissions and whether its
    file system is mounted read-only), so that a run writes nothing until it compiles; a missing one is made, and
    a file tried in it, once."""
    if path.is_dir():
        try:
            return os.access(path, os.W_OK | os.X_OK) and not os.statvfs(path).f_flag & os.ST_RDONLY
        except OSError:
            return False
    probe = path / f".ermrl-write-check-{os.getpid()}"
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe.write_bytes(b"")
    except OSError:
        return False
    finally:
        probe.unlink(missing_ok=True)
    return True


def enable(path: Path | None = None) -> Path | None:
    """Turns the cache on in ``path`` (default :func:`folder`) and returns it; None, leaving JAX's settings as they
    are, when it is off or the folder cannot be written. Without ``path`` and ``$ERMRL_COMPILE_CACHE``, a cache
    folder already given to JAX (``JAX_COMPILATION_CACHE_DIR``) is kept as it is, and returned."""
    import jax

    if path is None and VARIABLE not in os.environ and jax.config.jax_compilation_cache_dir:
        return Path(jax.config.jax_compilation_cache_dir)
    path = folder() if path is None else Path(path)
    if path is None:
        return None
    if not _writable(path):
        return None
    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
    jax.config.update("jax_compilation_cache_max_size", MAX_BYTES)  # least recently used entries go; locked
    return path

"""A training run's state at an iteration boundary, written now and then so that a stopped run resumes exactly.

A LunarLander test model (10 agents × 3M host steps) trains for hours; a stop used to lose all of it. Every few
minutes :meth:`ermrl.training.Trainer.run` writes, atomically, one file holding:

- the population's :class:`~ermrl.training.AgentState` (policies, optimizer, reservoir states and other env
  carries, keys), leaf by leaf, but the reservoirs' weights: they are fixed, and drawn again from the seeds and Φ
  (part of the identity) on resume (snapshots written before 2026-11-24 hold them too, and still resume);
- on the host backend, each env's :class:`~ermrl.envs.host_groups.EpisodeRecord` (how its running episode began
  and the actions since), from which the envs are rebuilt by replay;
- what the loop has gathered so far: finished episodes (stored sparsely), per-iteration metrics, the finite flags,
  and the compile and train times.

A rerun with the same identity (TrainConfig without the env workers, population, device count) continues from
the file and ends with the same Results, to the last bit, as a run that never stopped (tests/test_snapshots.py),
when it runs under the same versions and CPU as the run that wrote it (the file records them; a resume under others
says so).
A file for another identity, of another format, or damaged is ignored and the run starts over.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ermrl import provenance, storage
from ermrl.envs.host_groups import EpisodeRecord

FORMAT = "ermrl-run-snapshot"
VERSION = 1


class Snapshot(NamedTuple):
    """A run after ``iteration`` iterations."""

    iteration: int
    leaves: list[np.ndarray]
    """``jax.tree.leaves`` of the (padded) AgentState without its reservoirs, each with a leading agent axis."""
    envs: list[EpisodeRecord] | None
    """One record per host env slot; None on the JAX backend (the env states are in ``leaves``)."""
    finished: list[tuple[np.ndarray, np.ndarray]]
    """Per iteration: (returns, lengths), each (n, n_steps, n_envs); NaN and 0 where no episode ended."""
    metrics: list[dict[str, np.ndarray]]
    """Per iteration: name -> (n,) values."""
    finite: np.ndarray
    """(n,) bool."""
    compile_s: float
    train_s: float
    """Train time before the stop (the resumed run adds its own)."""
    software: dict | None = None
    """The versions and CPU it was computed under (:mod:`ermrl.provenance`); None when writing: this machine's, and
    when read from a file written before they were recorded."""


def identity(train_config, population, n_devices: int) -> dict:
    """What a run's state depends on, JSON-ready. The env workers and threads and the processes are left out:
    results do not depend on them."""
    train = storage.to_dict(train_config)
    train.pop("env_workers", None)
    train.pop("env_threads", None)
    train.pop("processes", None)
    return json.loads(json.dumps({
        "train": train, "devices": n_devices, "seeds": np.asarray(population.seeds).tolist(),
        "learning_rates": np.asarray(population.learning_rate).tolist(),
        "phi": {f: np.asarray(v).tolist() for f, v in population.phi._asdict().items()}},
        default=storage._json_default))


def write(path: Path, ident: dict, snap: Snapshot) -> None:
    """Writes ``snap`` for ``ident`` to ``path``, atomically (a stop while writing leaves the previous file)."""
    rets = np.stack([r for r, _ in snap.finished])  # (iterations, n, n_steps, n_envs)
    lengths = np.stack([n for _, n in snap.finished])
    where = np.nonzero(lengths > 0)
    meta = {"format": FORMAT, "version": VERSION, "identity": ident, "iteration": snap.iteration,
            "n_leaves": len(snap.leaves), "finished_shape": list(rets.shape[1:]),
            "finished_dtypes": [str(rets.dtype), str(lengths.dtype)], "metrics": list(snap.metrics[0]),
            "compile_s": snap.compile_s, "train_s": snap.train_s,
            "env_starts": None if snap.envs is None else [r.start for r in snap.envs],
            "software": snap.software or provenance.software()}
    arrays = {f"leaf/{i}": leaf for i, leaf in enumerate(snap.leaves)}
    arrays.update({"finished/where": np.stack(where).astype(np.int32), "finished/ret": rets[where],
                   "finished/length": lengths[where], "finite": snap.finite})
    arrays.update({f"metrics/{k}": np.stack([m[k] for m in snap.metrics]) for k in snap.metrics[0]})
    if snap.envs is not None:
        arrays["envs/action_counts"] = np.array([len(r.actions) for r in snap.envs], np.int64)
        arrays["envs/actions"] = np.concatenate([r.actions for r in snap.envs])
        arrays["envs/obs"] = np.stack([r.obs for r in snap.envs])
    with storage.atomic_path(Path(path)) as tmp, open(tmp, "wb") as f:
        np.savez(f, meta=np.array(json.dumps(meta)), **arrays)


def read(path: Path, ident: dict) -> Snapshot | None:
    """The snapshot at ``path`` if it was written for ``ident``; None when there is none, it is for another
    identity or format, or it cannot be read."""
    path = Path(path)
    if not path.is_file():
        return None
    try:
        kept, snap = read_any(path)
    except Exception:  # zipfile.BadZipFile, EOFError, OSError, KeyError, ValueError: start over
        return None
    return snap if kept == ident else None


def is_snapshot(path: Path) -> bool:
    """Whether the file at ``path`` is a readable training snapshot of this ermrl, of any identity."""
    try:
        read_any(path)
    except Exception:  # another format, or damaged: zipfile, NumPy, JSON or key errors
        return False
    return True


def read_any(path: Path) -> tuple[dict, Snapshot]:
    """(identity, snapshot) of the file at ``path`` whatever its identity, e.g. to look at a run in progress.
    Raises ValueError for a file of another format or version, and whatever NumPy raises for a damaged one."""
    with np.load(path, allow_pickle=False) as data:
        flat = {k: data[k] for k in data.files}
    meta = json.loads(str(flat["meta"]))
    if meta.get("format") != FORMAT or meta.get("version") != VERSION:
        raise ValueError(f"{path} is not a training snapshot of this ermrl ({FORMAT} v{VERSION})")
    return meta["identity"], _snapshot(meta, flat)


def _snapshot(meta: dict, flat: dict[str, np.ndarray]) -> Snapshot:
    n_it = meta["iteration"]
    ret_dtype, length_dtype = meta["finished_dtypes"]
    rets = np.full((n_it, *meta["finished_shape"]), np.nan, ret_dtype)
    lengths = np.zeros((n_it, *meta["finished_shape"]), length_dtype)
    where = tuple(flat["finished/where"].astype(np.intp))
    rets[where], lengths[where] = flat["finished/ret"], flat["finished/length"]
    metrics = [{k: flat[f"metrics/{k}"][i] for k in meta["metrics"]} for i in range(n_it)]
    envs = None
    if meta["env_starts"] is not None:
        bounds = np.concatenate([[0], np.cumsum(flat["envs/action_counts"])])
        actions = flat["envs/actions"]
        envs = [EpisodeRecord(start, actions[a:b], obs)
                for start, a, b, obs in zip(meta["env_starts"], bounds[:-1], bounds[1:], flat["envs/obs"])]
    return Snapshot(n_it, [flat[f"leaf/{i}"] for i in range(meta["n_leaves"])], envs,
                    list(zip(rets, lengths)), metrics, flat["finite"], meta["compile_s"], meta["train_s"],
                    meta.get("software"))

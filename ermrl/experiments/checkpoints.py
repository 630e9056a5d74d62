"""The finished models of an unfinished test phase, kept so that a rerun trains only what is missing.

A test phase trains its models one after another (ER-MRL at its learning rates, PPO on the same and on the full
observation, PPO-LSTM), which on a host env takes hours. As each model (one trained population, a *job*)
finishes, its :class:`~ermrl.training.results.Results` go whole into ``OUT.partial/JOB.npz`` beside the test
phase's folder ``OUT``, written atomically and tagged with the job's identity: the test phase's settings (its
TestConfig and Φ*'s trial), the job's name and labels, its TrainConfig and its population (seeds, learning rates,
Φ). A rerun loads a job whose identity is the same instead of training it again. The folder's ``settings.json``
holds the settings it was made for; a folder made for other settings is emptied first, so models trained for
other settings are never mixed in. When the test phase is written, the folder is removed.

A model still training has its latest snapshot there too, ``OUT.partial/JOB.snapshot``
(:mod:`ermrl.training.snapshots`, every few minutes), so that a stop in the middle of a model loses minutes, not
the model; it goes once the model is kept.
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path
from typing import Callable

import numpy as np

from ermrl import agent_files, provenance, storage
from ermrl.envs.spaces import EnvInfo
from ermrl.errors import ConfigError
from ermrl.training.results import Episodes, Policies, Results

FORMAT = "ermrl-test-job"
VERSION = 1
SETTINGS = "settings.json"


def partial_dir(out: Path) -> Path:
    """Where the finished models of the test phase ``out`` wait: ``out.parent / (out.name + ".partial")``."""
    out = Path(out)
    return out.parent / f"{out.name}.partial"


def snapshot_path(folder: Path, name: str) -> Path:
    """Where the job ``name`` keeps its training snapshot while it trains."""
    return Path(folder) / f"{name}.snapshot"


def plain(obj):
    """``obj`` as it reads back from JSON (tuples become lists, NumPy values Python ones), to compare identities."""
    return json.loads(json.dumps(obj, default=storage._json_default))


def open_partial(out: Path, settings: dict, recorded: Callable[[object], object] = lambda s: s) -> tuple[Path, bool]:
    """The partial folder of ``out`` for ``settings`` (JSON-ready), created if needed. Returns (folder,
    discarded): ``discarded`` is True when a folder made for other settings was there and has been emptied.
    ``recorded`` reads the settings the folder holds as they read today (older versions named some keys
    otherwise)."""
    folder = partial_dir(out)
    path = folder / SETTINGS
    discarded = False
    if folder.exists():
        try:
            same = recorded(storage.read_json(path)) == plain(settings)
        except (OSError, ValueError):  # missing or damaged: nothing in it can be trusted
            same = False
        if same:
            return folder, False
        _remove(folder)
        discarded = True
    storage.write_json(path, settings)
    return folder, discarded


OWN_FILES = re.compile(r"settings\.json|[^/]+\.(?:npz|snapshot)|\..+")
"""The names of what a partial folder holds: its settings, the kept jobs, the snapshot and atomic writes' hidden
temporary files."""


def _remove(folder: Path) -> None:
    """Removes the partial folder ``folder``; ConfigError, removing nothing, when it holds anything else
    (:data:`OWN_FILES`), so that a folder of the same name that ermrl did not make is never emptied."""
    entries = list(folder.iterdir()) if folder.is_dir() else [folder]
    foreign = sorted(p.name for p in entries if p.is_dir() or not OWN_FILES.fullmatch(p.name))
    if foreign:
        raise ConfigError(f"{folder} holds files that ermrl did not write there ({', '.join(foreign[:3])}); "
                          "move them away, then rerun")
    shutil.rmtree(folder)


def discard(out: Path) -> None:
    """Removes the partial folder of ``out``, if any (the test phase is written, or a rerun will redo it)."""
    if partial_dir(out).exists():
        _remove(partial_dir(out))


def save_job(folder: Path, name: str, identity: dict, results: Results) -> Path:
    """Writes ``results`` (A agents) to ``folder/NAME.npz`` atomically, with ``identity`` (JSON-ready)."""
    meta = {"format": FORMAT, "version": VERSION, "identity": plain(identity), "env_id": results.env_id,
            "total_timesteps": int(results.total_timesteps),
            "timesteps_per_iteration": int(results.timesteps_per_iteration),
            "compile_s": float(results.compile_s), "train_s": float(results.train_s),
            "env": None if results.policies is None else storage.to_dict(results.policies.env),
            "log_std": results.policies is not None and results.policies.log_std is not None,
            "phi": list(results.phi), "metrics": list(results.metrics),  # in order: agent files list Φ so
            "software": provenance.software()}
    episodes = results.episodes
    arrays = {"seeds": results.seeds, "learning_rate": results.learning_rate, "finite": results.finite,
              "episode_counts": np.array([len(e.ret) for e in episodes], np.int64),
              "episode_timestep": _concat([e.timestep for e in episodes], np.int64),
              "episode_ret": _concat([e.ret for e in episodes], np.float64),
              "episode_length": _concat([e.length for e in episodes], np.int64),
              **{f"phi/{k}": v for k, v in results.phi.items()},
              **{f"metrics/{k}": v for k, v in results.metrics.items()}}
    if results.policies is not None:
        arrays.update(agent_files.flatten(results.policies.actor, "actor"))
        arrays.update(agent_files.flatten(results.policies.critic, "critic"))
        if results.policies.log_std is not None:
            arrays["log_std"] = results.policies.log_std
        if results.policies.context_norm is not None:
            arrays.update(agent_files.flatten(results.policies.context_norm, "context_norm"))
    path = Path(folder) / f"{name}.npz"
    with storage.atomic_path(path) as tmp, open(tmp, "wb") as f:
        np.savez(f, meta=np.array(json.dumps(meta)), **{k: np.asarray(v) for k, v in arrays.items()})
    return path


def _concat(parts: list[np.ndarray], dtype) -> np.ndarray:
    return np.concatenate([np.asarray(p, dtype) for p in parts]) if parts else np.zeros(0, dtype)


def read_job(path: Path) -> tuple[dict, Results]:
    """(identity, results) of a file written by :func:`save_job`, e.g. to look at an unfinished test phase's
    models. Raises ValueError for a file of another format or version, and whatever NumPy raises for a damaged
    one."""
    with np.load(path, allow_pickle=False) as data:
        flat = {k: data[k] for k in data.files}
    meta = json.loads(str(flat.pop("meta")))
    if meta.get("format") != FORMAT or meta.get("version") != VERSION:
        raise ValueError(f"{path} is not a kept test model of this ermrl ({FORMAT} v{VERSION})")
    return meta["identity"], _results(meta, flat)


def load_job(folder: Path, name: str, identity: dict) -> Results | None:
    """The results saved by :func:`save_job` as ``NAME`` for this ``identity``; None when there are none, they
    were saved for another identity, or the file cannot be read (the job is then trained again)."""
    path = Path(folder) / f"{name}.npz"
    if not path.is_file():
        return None
    try:
        kept, results = read_job(path)
    except Exception:  # zipfile.BadZipFile, EOFError, OSError, KeyError, ValueError, ConfigError: train it again
        return None
    return results if kept == plain(identity) else None


def software_of(path: Path) -> dict | None:
    """The software versions (:mod:`ermrl.provenance`) a file written by :func:`save_job` was trained with;
    None for a file written before they were recorded."""
    with np.load(path, allow_pickle=False) as data:
        return json.loads(str(data["meta"])).get("software")


def _results(meta: dict, flat: dict[str, np.ndarray]) -> Results:
    """Rebuilds the :class:`Results` that :func:`save_job` wrote, array for array."""
    bounds = np.concatenate([[0], np.cumsum(flat["episode_counts"])])
    episodes = [Episodes(flat["episode_timestep"][a:b], flat["episode_ret"][a:b], flat["episode_length"][a:b])
                for a, b in zip(bounds[:-1], bounds[1:])]
    policies = None
    if meta["env"] is not None:
        env = storage.from_dict(EnvInfo, meta["env"], "env")
        policies = Policies(env, agent_files.unflatten(flat, "actor"), agent_files.unflatten(flat, "critic"),
                            flat["log_std"] if meta["log_std"] else None,
                            agent_files.unflatten(flat, "context_norm") or None)
    return Results(env_id=meta["env_id"], total_timesteps=meta["total_timesteps"],
                   timesteps_per_iteration=meta["timesteps_per_iteration"], seeds=flat["seeds"],
                   phi={k: flat[f"phi/{k}"] for k in meta["phi"]}, learning_rate=flat["learning_rate"],
                   episodes=episodes, finite=flat["finite"],
                   metrics={k: flat[f"metrics/{k}"] for k in meta["metrics"]},
                   compile_s=meta["compile_s"], train_s=meta["train_s"], policies=policies)

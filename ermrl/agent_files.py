"""The saved-agent file: one self-contained ``.npz`` per trained agent (``RUN/agents/seedS.npz``, a test phase's
``agents/MODEL/seedS.npz``), its final policy and a JSON record of how it was trained, written atomically.
:func:`ermrl.load_agent` reads one back and acts with it."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ermrl.atomic import atomic_path
from ermrl.errors import ConfigError
from ermrl.storage import _float_or_none, _json_default, to_dict

AGENT_FORMAT = "ermrl-agent"
AGENT_VERSION = 1
AGENTS_DIR = "agents"
"""A run folder's saved agents live in ``RUN/agents/`` (a test phase: ``agents/MODEL/``)."""
AGENT_FILES = AGENTS_DIR + r"/(?:[^/]+/)?seed\d+(?:-\d+)?\.npz"
"""The paths, relative to a run folder, of the agent files :func:`write_agents` writes there: a rerun of the
run removes those its new agents do not replace (:func:`ermrl.atomic.staged_folder`), and nothing else."""


def flatten(tree: dict, prefix: str) -> dict[str, np.ndarray]:
    """A nested dict of arrays as one flat dict keyed ``PREFIX/a/b`` (the .npz layout)."""
    out = {}
    for k, v in tree.items():
        out.update(flatten(v, f"{prefix}/{k}") if isinstance(v, dict) else {f"{prefix}/{k}": v})
    return out


def unflatten(flat: dict[str, np.ndarray], prefix: str) -> dict:
    """The inverse of :func:`flatten` for the keys under ``PREFIX/``."""
    tree: dict = {}
    for key, value in flat.items():
        if key.startswith(prefix + "/"):
            *path, leaf = key[len(prefix) + 1:].split("/")
            node = tree
            for part in path:
                node = node.setdefault(part, {})
            node[leaf] = value
    return tree


def write_agents(folder: Path | str, config, results, label: str = "") -> list[Path]:
    """Writes every agent of ``results`` (a :class:`~ermrl.training.results.Results` with ``policies``) trained
    with ``config`` (a TrainConfig) to ``folder/seedS.npz``, one self-contained file per agent.

    The file holds the final actor and critic parameters, the log std (Box), the context's normalization
    statistics (``context_norm/mean`` and ``/var``, with ``PPOConfig.normalize``) and a JSON record ``meta``: env id,
    env layout, the TrainConfig, Φ (K values each), seed, learning rate, fitness and the ermrl version. The
    reservoirs are not stored: :func:`ermrl.load_agent` regenerates them from Φ and the seed. Returns the paths."""
    from ermrl import __version__

    policies = results.policies
    if policies is None:
        raise ConfigError("these results hold no final policies to save; train them with Trainer.run")
    seeds = [int(s) for s in results.seeds]
    fit = results.fitness()
    paths = []
    for i, seed in enumerate(seeds):
        name = f"seed{seed}" if seeds.count(seed) == 1 else f"seed{seed}-{i}"
        meta = {"format": AGENT_FORMAT, "version": AGENT_VERSION, "ermrl_version": __version__,
                "env_id": results.env_id, "model": label, "seed": seed,
                "phi": {k: np.asarray(v[i], float).reshape(-1).tolist() for k, v in results.phi.items()},
                "learning_rate": float(results.learning_rate[i]), "fitness": _float_or_none(fit[i]),
                "diverged": not bool(results.finite[i]), "total_timesteps": int(results.total_timesteps),
                "env": to_dict(policies.env), "train": to_dict(config)}
        arrays = {**flatten(policies.actor, "actor"), **flatten(policies.critic, "critic")}
        arrays = {k: np.asarray(v[i], np.float32) for k, v in arrays.items()}
        if policies.log_std is not None:
            arrays["log_std"] = np.asarray(policies.log_std[i], np.float32)
        if policies.context_norm is not None:
            arrays.update({f"context_norm/{k}": np.asarray(v[i], np.float32) for k, v in policies.context_norm.items()})
        path = Path(folder) / f"{name}.npz"
        with atomic_path(path) as tmp, open(tmp, "wb") as f:
            np.savez(f, meta=np.array(json.dumps(meta, default=_json_default)), **arrays)
        paths.append(path)
    return paths


def read_agent(path: Path | str) -> tuple[dict, dict, dict, np.ndarray | None, dict | None]:
    """(meta, actor params, critic params, log_std, context_norm) of a file written by :func:`write_agents`; the
    params are nested dicts of float32 arrays as Flax has them, ``context_norm`` {"mean", "var"} (context_dim,)
    or None. Raises a one-line ConfigError for a missing or damaged file."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"agent file {path} does not exist; give a .npz file from a run folder's agents/ "
                          "(`ermrl train` and `ermrl test` save them unless --no-save-agents)")
    try:
        with np.load(path, allow_pickle=False) as data:
            flat = {k: data[k] for k in data.files}
        meta = json.loads(str(flat.pop("meta")))
        if meta.get("format") != AGENT_FORMAT:
            raise ValueError("no ermrl agent record")
    except Exception as e:  # zipfile.BadZipFile, EOFError, OSError, KeyError, ValueError, ...
        first = (str(e).strip().splitlines() or [""])[0]
        raise ConfigError(f"{path} is not a readable ermrl agent file ({type(e).__name__}: {first}); "
                          "it is damaged or was not written by ermrl: retrain, or load another agent") from None
    if meta.get("version", 0) > AGENT_VERSION:
        raise ConfigError(f"{path} was written by ermrl {meta.get('ermrl_version')} (agent format "
                          f"{meta['version']}); upgrade ermrl to load it")
    return (meta, unflatten(flat, "actor"), unflatten(flat, "critic"), flat.get("log_std"),
            unflatten(flat, "context_norm") or None)


def find_agents(folder: Path | str) -> list[Path]:
    """The saved agents under ``folder`` (a run, test phase or study folder, an agents/ folder or a model's folder
    in it, e.g. ``test/agents/ppo``), in a natural order: by folder, then by seed (seed2 before seed10)."""
    import re

    folder = Path(folder)
    natural = lambda part: [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", part)]
    inside = AGENTS_DIR in (folder.name, folder.parent.name)  # agents/ itself, or a test phase's model folder
    found = [p for p in folder.rglob("*.npz") if not p.name.startswith(".")
             and (inside or AGENTS_DIR in p.relative_to(folder).parts[:-1])]
    return sorted(found, key=lambda p: [natural(part) for part in p.relative_to(folder).parts])

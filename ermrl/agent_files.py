"""The saved-agent file: one self-contained ``.npz`` per trained agent (``RUN/agents/seedS.npz``, a test phase's
``agents/MODEL/seedS.npz``), its final policy and a JSON record of how it was trained, written atomically.
:func:`ermrl.load_agent` reads one back and acts with it."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ermrl.atomic import atomic_path
from ermrl.errors import ConfigError
from ermrl.storage import _float_or_none, _json_default, to_dict

if TYPE_CHECKING:
    from ermrl.agent import AgentConfig
    from ermrl.envs.spaces import EnvInfo

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
                          "(`ermrl train` and `ermrl test` save them with `save_agents`, the default)")
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


# -- checking an agent file's weights against its own record ---------------------------------------------


def _ppo_default(name: str):
    from ermrl.ppo.config import PPOConfig

    return PPOConfig.__dataclass_fields__[name].default


def expected_weights(ppo: dict, env: EnvInfo, config: AgentConfig) -> dict[str, tuple[tuple[int, ...], str]]:
    """{array in the file (``actor/params/Dense_0/kernel``, ...): (the shape its record implies, what in the record
    sets it)} of an agent file's policy, from its record: the env's observation and action sizes, the reservoirs
    (K, units, observed units, skip connection) and the PPO config (hidden widths, LSTM size, gSDE). The context
    normalization's statistics are left out (see :func:`check_weights`)."""
    hidden = [int(w) for w in ppo.get("hidden", _ppo_default("hidden"))]
    action = env.action
    lstm = ppo.get("model", "ff") == "lstm"
    if config.reservoirs == 0 or lstm:  # PPO-LSTM: reservoirs 0 (ermrl.training.recurrent.check)
        context, why = env.obs_dim, f"an observation of {env.obs_dim} values"
    else:
        skip = env.obs_dim + action.feature_dim + 1 if config.skip_connection else 0
        context = config.reservoirs * config.units_seen + skip
        seen = f"{config.units_seen} seen of {config.spec.units}" if config.observed_units is not None \
            else config.spec.units
        why = (f"{config.reservoirs} reservoir{'s' if config.reservoirs > 1 else ''} of {seen} units"
               + (f" plus a skip connection of {skip} inputs" if skip else ""))
    shapes: dict[str, tuple[tuple[int, ...], str]] = {}
    mlp = "params"
    if lstm:
        size = int(ppo.get("lstm_hidden_size", _ppo_default("lstm_hidden_size")))
        cell = f"an LSTM of {size} units"
        for net in ("actor", "critic"):
            shapes.update({f"{net}/lstm/kernel_x": ((context, 4 * size), f"{why} and {cell}"),
                           f"{net}/lstm/kernel_h": ((size, 4 * size), cell),
                           f"{net}/lstm/bias_ih": ((4 * size,), cell), f"{net}/lstm/bias_hh": ((4 * size,), cell)})
        context, why, mlp = size, cell, "mlp/params"
    layers = f"hidden layers {hidden}"
    for net, out, head in (("actor", action.policy_dim, f"{action.dim} action{'s' if action.dim > 1 else ''}"),
                           ("critic", 1, "one value")):
        widths = [context, *hidden, out]
        for i, (a, b) in enumerate(zip(widths, widths[1:])):
            into, outof = why if i == 0 else layers, layers if i < len(hidden) else head
            shapes[f"{net}/{mlp}/Dense_{i}/kernel"] = ((a, b), into if into == outof else f"{into} and {outof}")
            shapes[f"{net}/{mlp}/Dense_{i}/bias"] = ((b,), outof)
    if not action.discrete:
        sde = bool(ppo.get("use_sde", _ppo_default("use_sde")))
        actions = f"{action.dim} action{'s' if action.dim > 1 else ''}"
        shapes["log_std"] = ((hidden[-1], action.dim) if sde else (action.dim,),
                             actions + (f" and gSDE on {layers}" if sde else ""))
    return shapes


def check_weights(path: Path, ppo: dict, env: EnvInfo, config: AgentConfig, phi, actor: dict, critic: dict,
                  log_std: np.ndarray | None, context_norm: dict | None) -> None:
    """A one-line ConfigError naming ``path`` and the first array whose shape is not the one the file's record
    implies (:func:`expected_weights`), or that is missing or not implied at all: a damaged file, or one whose
    record and weights were written apart. Such a policy would fail inside a matrix product, or (a critic's
    layer) act on quietly."""
    got = {**flatten(actor, "actor"), **flatten(critic, "critic")}
    if log_std is not None:
        got["log_std"] = log_std
    try:
        expected = expected_weights(ppo, env, config)
    except (TypeError, ValueError, IndexError) as e:  # e.g. hidden widths that are not numbers
        raise ConfigError(f"{path} is damaged: its record's PPO settings are not what ermrl writes "
                          f"({type(e).__name__}: {e}); retrain, or load another agent") from None
    if ppo.get("model", "ff") == "lstm":  # files before bias_ih/bias_hh have one summed "bias"
        for net in ("actor", "critic"):
            if f"{net}/lstm/bias" in got and f"{net}/lstm/bias_ih" not in got:
                shape, why = expected.pop(f"{net}/lstm/bias_ih")
                expected.pop(f"{net}/lstm/bias_hh")
                expected[f"{net}/lstm/bias"] = (shape, why)
    problem = None
    for name, (shape, why) in expected.items():
        if name not in got:
            problem = f"it has no {name} array, which its record ({why}) implies"
        elif tuple(np.shape(got[name])) != shape:
            problem = (f"its record says {why}, so {name} should have shape {shape}, but it has "
                       f"{tuple(np.shape(got[name]))}")
        if problem:
            break
    extra = sorted(set(got) - set(expected))
    if problem is None and extra:
        problem = f"it has an array {extra[0]} that its record does not imply"
    k = config.reservoirs
    if problem is None and k and isinstance(phi, dict):
        sizes = {f: len(phi[f]) if isinstance(phi.get(f), list) else 0 for f in ("sr", "lr", "iss")}  # Phi's fields
        bad = next((f for f, n in sizes.items() if n != k), None)
        if bad is not None:
            problem = f"its record says {k} reservoir{'s' if k > 1 else ''} but its Φ has {sizes[bad]} {bad} values"
    if problem is None and context_norm is not None and ppo.get("normalize"):
        first = "actor/lstm/kernel_x" if "actor/lstm/kernel_x" in expected else "actor/params/Dense_0/kernel"
        dim = expected[first][0][0]  # what is normalized: the context (PPO-LSTM: the observation)
        bad = next((f for f in ("mean", "var") if np.shape(context_norm.get(f, ())) != (dim,)), None)
        if bad is not None:
            problem = (f"its normalization's {bad} has shape {np.shape(context_norm.get(bad, ()))}, not ({dim},) as "
                       "its record implies")
    if problem is not None:
        raise ConfigError(f"{path} is damaged: {problem}; retrain, or load another agent")

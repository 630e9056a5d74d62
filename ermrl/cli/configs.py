"""ermrl's configs built from a command's parsed options (:mod:`ermrl.cli.options` defines the flags).

Each builder takes the ``argparse.Namespace`` of a command and returns the dataclass the library runs with; a
value that no single flag's check can catch (a sampler without a search distribution, a non-positive
``--fixed-iss``, PPO settings an env's actions cannot take) is a one-line :class:`~ermrl.errors.ConfigError`.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from ermrl.cli.options import PPO_FIELDS, PPO_SWITCHES
from ermrl.errors import ConfigError


def convergence_rule(args):
    """The Convergence of ``--until-converged`` (None without it); ConfigError for a sampler without generations
    of a search distribution."""
    from ermrl.evolution.convergence import Convergence

    rule = Convergence(args.converged_width, args.converged_generations)  # bad values fail even without the switch
    if not args.until_converged:
        return None
    if getattr(args, "sampler", "cmaes") != "cmaes":
        raise ConfigError(f"--until-converged reads CMA-ES's search distribution; --sampler {args.sampler} has none "
                          "(use --sampler cmaes, or stop at --trials)")
    return rule


def agent_config(args, reservoirs: int | None = None):
    from ermrl.agent import AgentConfig
    from ermrl.reservoir import ReservoirSpec

    spec = ReservoirSpec(units=args.units, rc_connectivity=args.rc_connectivity,
                         input_connectivity=args.input_connectivity, bias=args.bias, bias_scaling=args.bias_scaling)
    return AgentConfig(reservoirs=args.reservoirs if reservoirs is None else reservoirs, spec=spec,
                       feed_action=args.feed_action, skip_connection=args.skip_connection,
                       observed_units=args.observed_units)


def ppo_config(args):
    from ermrl.ppo.config import PRESETS

    ppo = PRESETS[args.preset]
    changes = {}  # one replace, so that settings are checked together (e.g. batch_size against lstm_seq_len)
    if getattr(args, "model", "ff") == "lstm":  # the "model" options exist on `ermrl train` only
        changes.update(model="lstm", lstm_hidden_size=args.lstm_hidden, lstm_seq_len=args.lstm_seq_len)
    changes.update({name: getattr(args, name) for name in PPO_FIELDS if getattr(args, name, None) is not None})
    if args.learning_rate is not None:
        changes["learning_rate"] = args.learning_rate
    changes.update({name: getattr(args, name) for name in PPO_SWITCHES if getattr(args, name, None) is not None})
    if getattr(args, "net_arch", None) is not None:
        changes["hidden"] = tuple(args.net_arch)
    return dataclasses.replace(ppo, **changes) if changes else ppo


def describe_env(args, env_id: str):
    """``env_id``'s EnvInfo, checked before any work: an unknown id or a missing simulator, and PPO settings that
    cannot act in it (``--use-sde`` with discrete actions), each a one-line ConfigError."""
    from ermrl import envs

    info = envs.describe(env_id, args.backend)
    ppo_config(args).check_actions(env_id, info.action.discrete)
    return info


def train_config(args, env_id: str, reservoirs: int | None = None):
    from ermrl.training import TrainConfig

    return TrainConfig(env_id=env_id, total_timesteps=args.timesteps, agent=agent_config(args, reservoirs),
                       ppo=ppo_config(args), backend=args.backend, env_workers=args.env_workers,
                       env_threads=args.env_threads, processes=args.processes)


def search_space(args):
    from ermrl.evolution.search_space import SearchSpace

    if args.fixed_iss is not None and args.fixed_iss <= 0:
        raise ConfigError(f"--fixed-iss must be positive, got {args.fixed_iss}")
    return SearchSpace(args.reservoirs, (args.min_sr, args.max_sr), (args.min_lr, args.max_lr),
                       (args.min_iss, args.max_iss), args.fixed_iss)


def test_config(args):
    from ermrl.experiments.evaluation import TestConfig

    return TestConfig(seeds=args.seeds, timesteps=args.timesteps, learning_rates=tuple(args.learning_rates or ()),
                      baseline_learning_rate=args.baseline_learning_rate, env_id=args.env, trial=args.trial,
                      auc_steps=args.auc_steps, recurrent_baseline=args.recurrent_baseline)


def effective(args) -> dict:
    """Every option's final value (config file and flags applied), JSON-ready, for the run's record."""
    skip = {"command", "func", "config", "experiment_command", "debug"}
    return {k: (str(v) if isinstance(v, Path) else v) for k, v in sorted(vars(args).items()) if k not in skip}

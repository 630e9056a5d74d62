"""The study record: the user attribute ``ermrl`` in which a study keeps its :class:`EvolveConfig`."""

from __future__ import annotations

from ermrl.codec import from_dict, to_dict
from ermrl.errors import ConfigError
from ermrl.evolution.config import EvolveConfig
from ermrl.evolution.scoring import Baseline
from ermrl.evolution.search_space import SearchSpace
from ermrl.training.config import TrainConfig

STUDY_RECORD_VERSION = 2


def encode_study_record(config) -> dict:
    """The study user attribute ``ermrl`` of an :class:`~ermrl.evolution.config.EvolveConfig`.

    Flat keys a reader can use without decoding (env_id, envs, reservoirs, seeds, timesteps, learning_rate,
    search_space), plus the nested training config and the multi-env fitness constants."""
    return {
        "version": STUDY_RECORD_VERSION, "env_id": config.env_ids[0], "envs": list(config.env_ids),
        "reservoirs": config.space.reservoirs, "seeds": config.seeds, "timesteps": config.train.total_timesteps,
        "sampler": config.sampler, "popsize": config.generation_size, "sampler_seed": config.sampler_seed,
        "seed_schedule": config.seed_schedule,
        "learning_rate": config.train.ppo.learning_rate, "search_space": config.space.to_dict(),
        "train": to_dict(config.train), "trials": config.trials, "normalization": config.normalization,
        "baselines": [to_dict(b) for b in config.baselines],
    }


def decode_study_record(record: dict):
    """Inverse of :func:`encode_study_record` (also reads version-1 records, which had one env)."""
    try:
        train = from_dict(TrainConfig, record["train"], "train")
        return EvolveConfig(
            train=train, space=SearchSpace.from_dict(record["reservoirs"], record["search_space"]),
            trials=record["trials"], seeds=record["seeds"], sampler=record["sampler"], popsize=record["popsize"],
            sampler_seed=record.get("sampler_seed", 0), seed_schedule=record.get("seed_schedule", "fixed"),
            envs=tuple(record.get("envs", ())),
            normalization=record.get("normalization", "episodic"),
            baselines=tuple(from_dict(Baseline, b, "baselines") for b in record.get("baselines", ())))
    except (KeyError, TypeError) as e:
        raise ConfigError(f"the study's 'ermrl' record is incomplete or damaged ({type(e).__name__}: {e}); "
                          "it was not written by this version of `ermrl evolve`") from None

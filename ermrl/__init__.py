"""ermrl: Evolving Reservoirs for Meta Reinforcement Learning, with a whole population trained as one JAX program.

Importing it changes nothing in JAX or matplotlib: the CLI and :class:`~ermrl.training.trainer.Trainer` ask for
one JAX CPU device per core themselves (:mod:`ermrl.devices`), and figures are drawn without pyplot's global
state. The public names are in ``__all__``; each is imported on first use, so that ``import ermrl`` stays cheap.
"""

__version__ = "0.1.0"

_PUBLIC = {
    "load_agent": "ermrl.saved_agent",
    "ReservoirObservation": "ermrl.wrappers",
    "AgentConfig": "ermrl.agent",
    "Phi": "ermrl.agent",
    "DEFAULT_PHI": "ermrl.agent",
    "ReservoirSpec": "ermrl.reservoir",
    "PPOConfig": "ermrl.ppo.config",
    "TrainConfig": "ermrl.training.config",
    "Population": "ermrl.training.config",
    "Trainer": "ermrl.training.trainer",
    "train": "ermrl.training.trainer",
    "Results": "ermrl.training.results",
    "EvolveConfig": "ermrl.evolution.config",
    "SearchSpace": "ermrl.evolution.search_space",
    "evolve": "ermrl.evolution.evolve",
    "ConfigError": "ermrl.errors",
}
__all__ = ["__version__", *_PUBLIC]


def __getattr__(name: str):
    """The public names of ``__all__``, imported on first use."""
    if name in _PUBLIC:
        import importlib

        return getattr(importlib.import_module(_PUBLIC[name]), name)
    raise AttributeError(f"module 'ermrl' has no attribute {name!r}")

"""The inner loop ("development", paper §3): a population of agents trained as one program.

``trainer`` holds the population trainer; ``rollout`` the JAX scan and ``host_loop`` the Gymnasium loop that
collect its experience; ``results`` what a training returns.
"""

from ermrl.training.results import Results
from ermrl.training.trainer import AgentState, Population, Progress, TrainConfig, Trainer, make_agent_fns, train

__all__ = ["AgentState", "Population", "Progress", "Results", "TrainConfig", "Trainer", "make_agent_fns", "train"]

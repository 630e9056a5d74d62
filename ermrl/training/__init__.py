"""The inner loop ("development", paper §3): a population of agents trained as one program.

``config`` says what is trained (TrainConfig, Population); ``programs`` builds the per-agent functions and their
jitted population programs; ``trainer`` runs them; ``rollout`` the JAX scan and ``host_loop`` the Gymnasium loop
that collect its experience; ``results`` what a training returns.
"""

from ermrl.training.results import Results
from ermrl.training.config import Population, TrainConfig
from ermrl.training.programs import make_agent_fns
from ermrl.training.state import AgentState
from ermrl.training.trainer import Progress, Trainer, train

__all__ = ["AgentState", "Population", "Progress", "Results", "TrainConfig", "Trainer", "make_agent_fns", "train"]

"""Command-line options, one definition each, taken from the config dataclasses.

An option names the dataclass field it sets: its help is the field's docstring and its default the field's
default, so ``ermrl train``, ``evolve``, ``baselines`` and ``experiment run`` share one definition of every
agent, PPO and search option. ``--config FILE.toml`` (or .yaml) gives defaults for any option of a command,
keyed by the flag's name (``units = 50``, ``learning-rate = 1e-4``); flags on the command line override it.

The learning rate has one name everywhere, SB3's: ``--learning-rate`` (PPO's; in a test phase, the ER-MRL
agents'), ``--baseline-learning-rate`` (the test phase's PPO baselines'), ``--test-learning-rates`` (`ermrl
experiment run`'s). The flags of older versions (``--ppo-lr``, ``--ermrl-lr``, ``--test-lrs``) are refused with a
one-line error naming the new one (:func:`refuse_renamed`); a config file's old keys still set the new options.

Why argparse and not tyro, simple-parsing or jsonargparse, which also build a CLI from dataclasses and their field
docstrings: one ermrl command flattens fields of several dataclasses (``ReservoirConfig``, ``PPOConfig``,
``EvolutionConfig``, ...) into one flat set of flags whose names are not the fields' (``--leak-rate`` sets
``SearchSpace.lr`` bounds, ``--learning-rate`` sets ``PPOConfig.learning_rate``), and many of its defaults are "the
preset's value" resolved after parsing, with errors that must name a flag and exit 2 before any work. Those
libraries prefix nested fields (``--ppo.learning-rate``), take a dataclass's default as the flag's default, and
print their own error formats, so each of these would need per-field overrides that amount to this table again,
plus a dependency. The table here is that one definition: an :class:`Option` per flag.

The same definitions turn the library's messages into the command line's: a library error names a parameter by
its own name in backquotes ("`trials` must be <= 100,000"), and :func:`ermrl.cli.messages.cli_message` shows the flag that sets it
("--trials must be <= 100,000").
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import functools
import inspect
import re
import textwrap
from pathlib import Path

from ermrl.errors import ConfigError
from ermrl.model_labels import PHI_NAMES


BASELINE_STORE_HELP = ("keep the trained PPO baselines in DIR and reuse them: a test phase whose baseline (env, seeds, "
                       "budget, PPO settings; any Φ*) is there loads it instead of training it again. Default: "
                       "train every baseline.")


@functools.cache
def field_docs(cls) -> dict[str, str]:
    """{field name: the first paragraph of the docstring under it} of a dataclass, read from its source: the help
    text. Paragraphs after a blank line are notes for developers and stay out of ``--help``."""
    tree = ast.parse(textwrap.dedent(inspect.getsource(cls)))
    body = tree.body[0].body
    docs = {}
    for node, after in zip(body, body[1:]):
        if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name) and isinstance(after, ast.Expr) \
                and isinstance(after.value, ast.Constant) and isinstance(after.value.value, str):
            docs[node.target.id] = " ".join(textwrap.dedent(after.value.value).split("\n\n")[0].split())
    return docs


def plain(doc: str) -> str:
    """A docstring as help text: Sphinx roles (``:mod:`x` ``) and double backquotes dropped, keeping the names."""
    import re

    return re.sub(r"``([^`]*)``", r"\1", re.sub(r":\w+:`~?([^`]*)`", r"\1", doc))


@dataclasses.dataclass(frozen=True)
class Option:
    """One flag. With ``owner`` and ``field``, its help and default come from that dataclass field."""

    flag: str
    owner: type | None = None
    field: str | None = None
    help: str | None = None
    """Help text when there is no field, or a short note added before the field's docstring."""
    default: object = None
    """Overrides the field's default (e.g. None for 'take the preset's value')."""
    kwargs: dict = dataclasses.field(default_factory=dict)
    """argparse extras: type, nargs, choices, action, metavar."""
    name: str | None = None
    """The value's name (argparse's dest, a config file's key) when it is not the flag's."""
    item: int | None = None
    """The item of the field's tuple that the flag sets, if it sets one (``--min-sr``: 0 of SearchSpace.sr);
    library messages name it ``sr[0]``."""
    gives: str | None = None
    """The library parameter that the flag gives where it sets no field (``--tensorboard``: the ``logdir`` of
    :mod:`ermrl.analysis.tensorboard`'s functions), named so in library messages."""

    @property
    def dest(self) -> str:
        return self.name or self.flag.lstrip("-").replace("-", "_")

    @property
    def parameter(self) -> str | None:
        """The library's name of what the flag sets: the field (``trials``), an item of it (``sr[0]``) or
        :attr:`gives`; None for a flag of the command line only (``--preset``)."""
        if self.field is None:
            return self.gives
        return self.field if self.item is None else f"{self.field}[{self.item}]"

    def field_default(self):
        if self.owner is None or self.default is not None:
            return self.default
        f = {f.name: f for f in dataclasses.fields(self.owner)}[self.field]
        return f.default if f.default is not dataclasses.MISSING else f.default_factory()

    def add_to(self, parser: argparse.ArgumentParser) -> None:
        doc = plain(field_docs(self.owner).get(self.field, "")) if self.owner else ""
        text = " ".join(p for p in (self.help, doc) if p).replace("%", "%%")
        kwargs = dict(self.kwargs)
        if kwargs.get("action") != "store_true":
            kwargs.setdefault("default", self.field_default())
        action = parser.add_argument(self.flag, help=text, dest=self.dest, **kwargs)
        if self.parameter is not None:
            sets(action, self.parameter, *(() if self.field is None else (self.owner,)))


GIVES = "ermrl_gives"
"""The attribute of an argparse action that holds the (owner, parameter) pairs its flag sets (:func:`sets`)."""


def sets(action: argparse.Action, parameter: str, *owners) -> argparse.Action:
    """Records that the flag of ``action`` gives the library's ``parameter`` of each of ``owners`` (dataclasses
    or functions; none: of any), so that :func:`ermrl.cli.messages.cli_message` shows the flag where a library message names the
    parameter. For a flag whose dest is not the parameter's name (``ermrl evolve --env``: EvolveConfig's
    ``envs``); an :class:`Option` records its field itself. Returns ``action``."""
    setattr(action, GIVES, getattr(action, GIVES, ()) + tuple((owner, parameter) for owner in owners or (None,)))
    return action


def path(value: str) -> Path:
    """argparse type of every path option: a non-empty path (an empty one would mean the current folder)."""
    if not value.strip():
        raise argparse.ArgumentTypeError("is an empty path; give a path, or leave the option out for its default")
    return Path(value)


def storage(value: str) -> str:
    """argparse type of --storage: a non-empty Optuna storage URL or journal file path."""
    if not value.strip():
        raise argparse.ArgumentTypeError("is empty; give sqlite:///PATH.db, a journal file PATH.log or a database "
                                         "URL, or leave --storage out for the study's own sqlite file")
    return value


MAX_STOP_AFTER_S = 366 * 86_400
"""The longest --stop-after, in seconds (a year)."""


def duration(value: str) -> float:
    """argparse type of --stop-after: a duration with units, hours, minutes and seconds in that order (``2h30m``,
    ``90m``, ``45s``, ``1.5h``), in seconds."""
    import re

    match = re.fullmatch(r"(?:(\d+(?:\.\d*)?)h)?(?:(\d+(?:\.\d*)?)m)?(?:(\d+(?:\.\d*)?)s)?", value.strip())
    if not value.strip() or match is None:
        raise argparse.ArgumentTypeError(f"must be a duration with units such as 2h30m, 90m or 45s, got {value!r}")
    h, m, sec = (float(g or 0) for g in match.groups())
    seconds = 3600 * h + 60 * m + sec
    if not 0 < seconds <= MAX_STOP_AFTER_S:
        raise argparse.ArgumentTypeError(f"must be longer than 0 s and at most a year (8784h), got {value!r}")
    return seconds


def _auto_or_count(value: str, low: int, high: int | None = None):
    """``value`` as 'auto' or an integer in [low, high] (no upper bound when ``high`` is None); else the
    ArgumentTypeError that names the range."""
    if value == "auto":
        return value
    try:
        n = int(value)
    except ValueError:
        n = None
    if n is None or n < low or (high is not None and n > high):
        shown = f"in {low}..{high}" if high is not None else f">= {low}"
        raise argparse.ArgumentTypeError(f"must be 'auto' or an integer {shown}, got {value!r}")
    return n


def threads(value: str):
    """argparse type of --env-threads: 'auto' or an integer in 1..4096."""
    return _auto_or_count(value, 1, 4096)


def processes(value: str) -> int:
    """argparse type of --processes: an integer in 1..MAX_PROCESSES."""
    from ermrl.training.config import MAX_PROCESSES

    try:
        n = int(value)
    except ValueError:
        n = None
    if n is None or not 1 <= n <= MAX_PROCESSES:
        raise argparse.ArgumentTypeError(f"must be an integer in 1..{MAX_PROCESSES}, got {value!r}")
    return n


def workers(value: str):
    """argparse type of --env-workers: 'auto' or an integer >= 0."""
    return _auto_or_count(value, 0)


def _groups() -> dict[str, list[Option]]:
    """The option groups; imported lazily so that ``ermrl --help`` does not import JAX."""
    from ermrl.agent import AgentConfig
    from ermrl.evolution.config import EvolveConfig
    from ermrl.evolution.convergence import Convergence
    from ermrl.evolution.search_space import SearchSpace
    from ermrl.evolution.worker_config import WorkerConfig
    from ermrl.experiments.evaluation import TestConfig
    from ermrl.ppo.config import PPOConfig
    from ermrl.reservoir import ReservoirSpec
    from ermrl.training import TrainConfig

    space = [Option(f"--{b}-{FLAG_NAMES.get(hp, hp)}", SearchSpace, hp, name=f"{b}_{hp}", item=item,
                    help=f"{'lower' if b == 'min' else 'upper'} log-uniform bound of the {PHI_NAMES[hp]}.",
                    default=getattr(SearchSpace, hp)[item], kwargs={"type": float})
             for hp in ("sr", "lr", "iss") for item, b in enumerate(("min", "max"))]
    return {
        "env": [Option("--timesteps", TrainConfig, "total_timesteps", kwargs={"type": int}),
                Option("--backend", TrainConfig, "backend", kwargs={"choices": ["auto", "jax", "mujoco", "host"]}),
                Option("--env-workers", TrainConfig, "env_workers", kwargs={"type": workers, "metavar": "N|auto"}),
                Option("--env-threads", TrainConfig, "env_threads", kwargs={"type": threads, "metavar": "N|auto"}),
                Option("--processes", TrainConfig, "processes", kwargs={"type": processes, "metavar": "N"})],
        "agent": [
            Option("--reservoirs", AgentConfig, "reservoirs", kwargs={"type": int}),
            Option("--units", ReservoirSpec, "units", kwargs={"type": int}),
            Option("--bias", ReservoirSpec, "bias", kwargs={"choices": ["bernoulli", "none"]}),
            Option("--rc-connectivity", ReservoirSpec, "rc_connectivity", kwargs={"type": float}),
            Option("--input-connectivity", ReservoirSpec, "input_connectivity", kwargs={"type": float}),
            Option("--bias-scaling", ReservoirSpec, "bias_scaling", kwargs={"type": float}),
            Option("--feed-action", AgentConfig, "feed_action", kwargs={"choices": ["previous", "none"]}),
            Option("--skip-connection", AgentConfig, "skip_connection", kwargs={"action": "store_true"}),
            Option("--observed-units", AgentConfig, "observed_units", kwargs={"type": int}),
        ],
        "model": [Option("--model", PPOConfig, "model", kwargs={"choices": ["ff", "lstm"]},
                         help="'lstm' trains the recurrent baseline (PPO-LSTM; implies --no-reservoir)."),
                  Option("--lstm-hidden", PPOConfig, "lstm_hidden_size", kwargs={"type": int}),
                  Option("--lstm-seq-len", PPOConfig, "lstm_seq_len", kwargs={"type": int})],
        "ppo": [Option("--preset", help="PPO settings: 'sb3' = stable-baselines3's defaults (the paper); "
                                        "'fast' = 8 envs, 4 epochs.", default="sb3", kwargs={"choices": ["sb3", "fast"]}),
                Option("--learning-rate", PPOConfig, "learning_rate", help="Default: the preset's (3e-4).",
                       kwargs={"type": float, "default": None}),
                *(Option(f"--{name.replace('_', '-')}", PPOConfig, name,
                         help=f"Default: the preset's ({getattr(PPOConfig(), name)} in sb3).",
                         kwargs={"type": kind, "default": None}) for name, kind in PPO_FIELDS.items()),
                Option("--normalize", PPOConfig, "normalize", help="Default: off (SB3's PPO, the paper).",
                       kwargs={"action": argparse.BooleanOptionalAction, "default": None}),
                Option("--use-sde", PPOConfig, "use_sde", help="Default: off (SB3's PPO, the paper).",
                       kwargs={"action": argparse.BooleanOptionalAction, "default": None}),
                Option("--sde-sample-freq", PPOConfig, "sde_sample_freq", help="Default: -1.",
                       kwargs={"type": int, "default": None}),
                Option("--net-arch", PPOConfig, "hidden", help="Default: 64 64 (SB3's MlpPolicy).",
                       kwargs={"type": int, "nargs": "+", "default": None, "metavar": "WIDTH"}),
                Option("--activation", PPOConfig, "activation", help="Default: tanh.",
                       kwargs={"choices": ["tanh", "relu"], "default": None}),
                Option("--ortho-init", PPOConfig, "ortho_init", help="Default: on.",
                       kwargs={"action": argparse.BooleanOptionalAction, "default": None})],
        "search": [Option("--trials", EvolveConfig, "trials", kwargs={"type": int}),
                   Option("--sampler", help="cmaes (Optuna's CmaEsSampler, the paper), random or tpe.",
                          default="cmaes"),
                   Option("--popsize", EvolveConfig, "popsize", kwargs={"type": int}),
                   Option("--sampler-seed", EvolveConfig, "sampler_seed", kwargs={"type": int}),
                   Option("--seed-schedule", EvolveConfig, "seed_schedule", kwargs={"choices": ["fixed", "generation"]}),
                   Option("--fixed-iss", SearchSpace, "fixed_iss", kwargs={"type": float}),
                   Option("--normalization", EvolveConfig, "normalization",
                          kwargs={"choices": ["episodic", "reference"]}), *space],
        "workers": [Option("--batch", WorkerConfig, "batch", kwargs={"type": int}),
                    Option("--worker-index", WorkerConfig, "worker_index", kwargs={"type": int}),
                    Option("--heartbeat-interval", WorkerConfig, "heartbeat_interval", kwargs={"type": int}),
                    Option("--grace-period", WorkerConfig, "grace_period", kwargs={"type": int}),
                    Option("--snapshots", WorkerConfig, "snapshots", kwargs={"type": path, "metavar": "DIR"})],
        "stop": [Option("--stop-after", help="stop cleanly between two generations once the next one would not end "
                        "within DURATION of the command's start (2h30m, 90m, 45s), judged by the time the last one "
                        "took, and exit with status 75; rerun the same command to continue. For a job with a time "
                        "limit (a batch scheduler's walltime) or a machine lent for some hours. Default: no limit.",
                        kwargs={"type": duration, "metavar": "DURATION"}, gives="stop_at")],
        "convergence": [
            Option("--until-converged", help="also stop once CMA-ES has converged: every searched parameter's spread "
                   "(the search distribution's standard deviation, in decades) below --converged-width for "
                   "--converged-generations generations in a row; recorded in the study. CMA-ES only.",
                   kwargs={"action": "store_true"}),
            Option("--converged-width", Convergence, "width", kwargs={"type": float, "metavar": "DECADES"}),
            Option("--converged-generations", Convergence, "generations", kwargs={"type": int, "metavar": "G"})],
        "test": [Option("--seeds", TestConfig, "seeds", kwargs={"type": int}),
                 Option("--timesteps", TestConfig, "timesteps", kwargs={"type": int}),
                 Option("--learning-rate", TestConfig, "learning_rates", name="learning_rates",
                        kwargs={"type": float, "nargs": "+", "default": None, "metavar": "RATE"}),
                 Option("--baseline-learning-rate", TestConfig, "baseline_learning_rate",
                        kwargs={"type": float, "metavar": "RATE"}),
                 Option("--env", TestConfig, "env_id", kwargs={}),
                 Option("--trial", TestConfig, "trial", kwargs={"type": int}),
                 Option("--auc-steps", TestConfig, "auc_steps", kwargs={"type": int}),
                 Option("--recurrent-baseline", TestConfig, "recurrent_baseline", kwargs={"action": "store_true"}),
                 Option("--agents-per-run", help="train each model in groups of at most N agents (a seed at one "
                        "learning rate), each kept in OUT.partial/ when it finishes, so that a stop loses one group "
                        "at most: for models that take hours (LunarLander at 3M steps). Results are the "
                        "same up to rounding. Default: all agents of a model at once (the fastest).",
                        kwargs={"type": int, "metavar": "N"}),
                 Option("--baseline-store", help=BASELINE_STORE_HELP, kwargs={"type": path, "metavar": "DIR"})],
        "agents": [Option("--save-agents", help="save every agent's final policy in the run folder's agents/ "
                                                "(one .npz each, about 100 kB at the default sizes; "
                                                "ermrl.load_agent loads one).",
                          default=True, kwargs={"action": argparse.BooleanOptionalAction})],
        "tensorboard": [Option("--tensorboard", help="also write TensorBoard logs here after training: one run "
                                                     "folder per agent (LABEL_seedN) with SB3's tag names "
                                                     "(rollout/ep_rew_mean; rollout/ep_len_mean, time/fps, train/* "
                                                     "where known), the env step count as the global step.",
                               kwargs={"type": path, "metavar": "DIR"}, gives="logdir")],
    }


PPO_FIELDS = {"n_envs": int, "n_steps": int, "batch_size": int, "n_epochs": int, "gamma": float, "gae_lambda": float,
              "clip_range": float, "ent_coef": float, "vf_coef": float, "max_grad_norm": float}
"""The PPOConfig fields that have a flag of their own (``--gamma``, ``--n-steps``, ...), named as SB3's arguments;
each overrides the preset's value, as ``--learning-rate`` does (e.g. rl-baselines3-zoo's tuned settings for an env)."""

PPO_SWITCHES = ("normalize", "use_sde", "sde_sample_freq", "activation", "ortho_init")
"""The PPOConfig fields beyond SB3's PPO defaults that rl-baselines3-zoo's settings use, with flags of their own
(the policy's widths too: ``--net-arch``, PPOConfig.hidden)."""

AGENT_DESTS = ("reservoirs", "units", "bias", "rc_connectivity", "input_connectivity", "bias_scaling", "feed_action",
               "skip_connection", "observed_units", "preset", "learning_rate", *PPO_FIELDS, *PPO_SWITCHES, "net_arch",
               "timesteps", "backend", "env_workers", "env_threads", "processes")
"""What every command that trains agents accepts (``train``, ``evolve``, ``baselines``)."""


FLAG_NAMES = {"lr": "leak-rate"}
"""Φ's flags spell out the leak rate: in RL, "lr" is a learning rate (PPO's is ``--learning-rate``)."""
LEAK_RATE_NOT_LR = ("{flag} is ambiguous: the reservoir's leak rate is {leak}, PPO's learning rate is "
                    "--learning-rate (in a test phase, the PPO baselines': --baseline-learning-rate)")
RENAMED = "{old} is now {new} ({meaning})"
"""The one-line error of a flag that older versions named otherwise."""
RENAMED_FLAGS = {
    "ppo": [("--ppo-lr", "--learning-rate", "PPO's learning rate")],
    "test": [("--ermrl-lr", "--learning-rate", "the ER-MRL agents' learning rates"),
             ("--ppo-lr", "--baseline-learning-rate", "the PPO baselines' learning rate")],
}
"""{option group: [(old flag, its flag now, what it sets)]}: the flags each group refuses under their old names."""


class Refused(argparse.Action):
    """A flag that is refused with ``message`` (a one-line error), whatever values follow it; not in --help.
    ``renamed``: the dest of the option that it is now, which a config file's key of the old name sets."""

    def __init__(self, option_strings, dest, message: str = "", renamed: str | None = None, **kwargs):
        super().__init__(option_strings, dest, nargs="*", default=argparse.SUPPRESS, help=argparse.SUPPRESS)
        self.message = message
        self.renamed = renamed

    def __call__(self, parser, namespace, values, option_string=None):
        parser.error(self.message)


def refuse_lr(parser: argparse.ArgumentParser, flag: str, leak: str) -> None:
    """Refuses ``flag`` (``--lr``, ``--min-lr``, ...) with the one-line error naming both of its meanings."""
    parser.add_argument(flag, action=Refused, dest=_refused_dest(flag),
                        message=LEAK_RATE_NOT_LR.format(flag=flag, leak=leak))


def refuse_renamed(parser: argparse.ArgumentParser, old: str, new: str, meaning: str) -> None:
    """Refuses ``old``, the flag that older versions named ``new`` (an option of ``parser``), with the one-line
    error naming ``new`` and ``meaning`` (what it sets); a config file's key ``old`` sets ``new``."""
    (dest,) = [a.dest for a in parser._actions if new in a.option_strings]
    parser.add_argument(old, action=Refused, dest=_refused_dest(old), renamed=dest,
                        message=RENAMED.format(old=old, new=new, meaning=meaning))


def _refused_dest(flag: str) -> str:
    return f"refused_{flag.lstrip('-').replace('-', '_')}"


def add_options(parser: argparse.ArgumentParser, *groups: str, skip: tuple[str, ...] = ()) -> None:
    table = _groups()
    for group in groups:
        for option in table[group]:
            if option.flag not in skip:
                option.add_to(parser)
        for old, new, meaning in RENAMED_FLAGS.get(group, ()):
            if new not in skip:
                refuse_renamed(parser, old, new, meaning)
        if group == "search":
            refuse_lr(parser, "--min-lr", "--min-leak-rate")
            refuse_lr(parser, "--max-lr", "--max-leak-rate")


def add_config_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", type=path, default=None, metavar="FILE",
                        help="a TOML or YAML file of option values keyed by flag name (e.g. units = 50); "
                             "flags given on the command line override it")

"""Library errors name the library's parameters, not the command line's flags: a user who builds
``EvolveConfig(trials=10**9)`` reads "`trials` must be <= 100,000", with the dataclass or function whose
parameter it is as the error's ``owner``; the command line shows each of those names as its flag, from the one
definition of its options (``ermrl.cli.options``), so that its messages stay what test_bad_input.py holds."""

from __future__ import annotations

import ast
import dataclasses
import importlib
import inspect
import re
from pathlib import Path

import pytest

from ermrl.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1] / "ermrl"

FLAG = re.compile(r"--(?:[a-z]|\{)")
"""A flag in a message: ``--trials``, or one built from a name (``--{name}``)."""
COMMAND = re.compile(r"`ermrl [^`]*`|\(ermrl [a-z-]+ [^)]*\)")
"""A command line that a message suggests (``rerun `ermrl test --env X` ``): its flags are the command's."""
NAME = re.compile(r"`([A-Za-z_]\w*)(?:\[\d+\])?`")
"""A parameter named by a library message."""
RAISERS = {"ConfigError", "RunFailed", "ShortEpisode", "ValueError", "print", "warn"}
"""Calls whose text reaches a user: the errors the command line shows as one line, and warnings."""


def _library_files() -> list[Path]:
    return sorted(p for p in ROOT.rglob("*.py") if p.relative_to(ROOT).parts[0] != "cli")


def _text(node: ast.AST) -> str:
    """The text of a str constant or f-string, each formatted value as ``{...}`` with the strings inside it
    (``f"--{name}"``: "--{}"; ``f"`ermrl test{' --env ' + env}`"``: "`ermrl test{ --env }`"); "" for anything
    else."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return node.value
    if isinstance(node, ast.JoinedStr):
        return "".join(v.value if isinstance(v, ast.Constant) else "{" + "".join(_texts(v.value)) + "}"
                       for v in node.values)
    return ""


def _texts(node: ast.AST) -> list[str]:
    """Every str constant and f-string in ``node``, outermost first (adjacent literals are one already)."""
    if text := _text(node):
        return [text]
    return [t for child in ast.iter_child_nodes(node) for t in _texts(child)]


def _messages(path: Path) -> list[tuple[int, str]]:
    """(line, text) of what ``path`` shows a user: the strings in the calls of :data:`RAISERS`, its module-level
    str constants (e.g. advice that ends a message) and the str defaults of its functions' parameters (e.g. the
    name a path check gives its path)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            f = node.func
            name = f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else ""
            if name in RAISERS:
                found += [(node.lineno, t) for a in [*node.args, *(k.value for k in node.keywords)]
                          for t in _texts(a)]
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            found += [(d.lineno, _text(d)) for d in node.args.defaults + node.args.kw_defaults if d and _text(d)]
    for node in tree.body:
        if isinstance(node, ast.Assign) and _text(node.value):
            found.append((node.lineno, _text(node.value)))
    return found


def test_no_library_message_names_a_flag():
    """The library's messages name parameters (`trials`); a flag (--trials) appears only in a command line that
    a message suggests running (`ermrl evolve --study NAME`). ermrl/cli/ is the command line: it may."""
    bad = [f"{path.relative_to(ROOT.parent)}:{line}: {text!r}" for path in _library_files()
           for line, text in _messages(path) if FLAG.search(COMMAND.sub("", text))]
    assert bad == []


def _owner(module, node: ast.Call, classes: list[str], imported: dict[str, str]):
    """The object that a ``ConfigError(..., owner=X)`` call names (None without one): ``type(self)`` in a method
    is its class, a name one of the module's or one it imports (inside a function too); ``...`` for a variable."""
    owner = next((k.value for k in node.keywords if k.arg == "owner"), None)
    if owner is None:
        return None
    if isinstance(owner, ast.Call) and isinstance(owner.func, ast.Name) and owner.func.id == "type":
        return getattr(module, classes[-1])
    assert isinstance(owner, ast.Name), ast.dump(owner)
    if hasattr(module, owner.id):
        return getattr(module, owner.id)
    if owner.id in imported:
        return getattr(importlib.import_module(imported[owner.id]), owner.id)
    return ...  # a parameter passed on (study._check_same_config's owner)


def _parameters(owner) -> set[str]:
    if dataclasses.is_dataclass(owner):
        return {f.name for f in dataclasses.fields(owner)}
    return set(inspect.signature(owner).parameters)


def test_every_owner_has_the_parameters_its_message_names():
    """A ConfigError with an owner names only that dataclass's fields or that function's arguments, so that a
    library user finds them, and the command line finds their flags."""
    checked = 0
    for path in _library_files():
        text = path.read_text(encoding="utf-8")
        if "owner=" not in text:
            continue
        module = importlib.import_module(".".join(path.relative_to(ROOT.parent).with_suffix("").parts))
        tree = ast.parse(text)
        imported = {a.asname or a.name: n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)
                    and n.module and n.module.startswith("ermrl") for a in n.names}

        def visit(node, classes):
            nonlocal checked
            if isinstance(node, ast.ClassDef):
                classes = [*classes, node.name]
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in RAISERS:
                owner = _owner(module, node, classes, imported)
                texts = [t for a in node.args for t in _texts(a)]
                names = {m for t in texts for m in NAME.findall(t)}
                named = names or any("`{" in t for t in texts)  # `{name}`: a field named in a loop over them
                if owner is not None and owner is not ...:
                    assert named and names <= _parameters(owner), (path, node.lineno, names, owner)
                    checked += 1
            for child in ast.iter_child_nodes(node):
                visit(child, classes)

        visit(tree, [])
    assert checked >= 40


# -- the library's messages, as a library user reads them ----------------------------------------------


def _evolve_config(**changes):
    from ermrl.evolution.config import EvolveConfig
    from ermrl.evolution.search_space import SearchSpace
    from ermrl.training import TrainConfig

    return EvolveConfig(train=TrainConfig(env_id="CartPoleNoVel-v1"), space=SearchSpace(), **changes)


def _raised(make) -> ConfigError:
    with pytest.raises(ConfigError) as e:
        make()
    return e.value


def test_config_dataclasses_name_their_fields():
    from ermrl.evolution.config import EvolveConfig
    from ermrl.evolution.search_space import SearchSpace
    from ermrl.evolution.worker_config import WorkerConfig
    from ermrl.experiments.evaluation import TestConfig
    from ermrl.experiments.runner import TestBudget

    cases = [
        (lambda: _evolve_config(trials=10**6), EvolveConfig,
         "`trials` must be <= 100,000 (the paper's studies have 900), got 1000000"),
        (lambda: _evolve_config(seeds=0), EvolveConfig, "`seeds` must be >= 1, got 0"),
        (lambda: _evolve_config(envs=("CartPole-v1", "CartPole-v1")), EvolveConfig,
         "`envs` lists an env twice: CartPole-v1, CartPole-v1; give each env once"),
        (lambda: WorkerConfig(batch=0), WorkerConfig, "`batch` must be >= 1, got 0"),
        (lambda: WorkerConfig(heartbeat_interval=10, grace_period=10), WorkerConfig,
         "`grace_period` (10 s) must be longer than `heartbeat_interval` (10 s), or live trials would be failed "
         "as lost"),
        (lambda: SearchSpace(sr=(10.0, 1.0)), SearchSpace,
         "bad sr bounds [10.0, 1.0]: need 0 < `sr[0]` < `sr[1]` (log-uniform)"),
        (lambda: SearchSpace(lr=(0.01, 2.0)), SearchSpace,
         "bad leak-rate bounds [0.01, 2.0]: a leak rate is at most 1; set `lr[1]` to 1"),
        (lambda: TestConfig(auc_steps=0), TestConfig, "`auc_steps` must be >= 1, got 0"),
        (lambda: TestConfig(env_id=" "), TestConfig,
         "`env_id` is empty; give an env id, or leave `env_id` out to test on the evolution's env"),
        (lambda: TestBudget(seeds=0), TestBudget, "`seeds` must be >= 1, got 0"),
        (lambda: TestBudget(learning_rates=(1e-4, 1e-4)), TestBudget,
         "`learning_rates` gives 0.0001 twice; give each learning rate once"),
    ]
    for make, owner, message in cases:
        e = _raised(make)
        assert (str(e), e.owner) == (message, owner)


def test_library_functions_name_their_arguments(tmp_path):
    from ermrl import envs
    from ermrl.analysis.tensorboard import check_logdir
    from ermrl.analysis.video import write_video
    from ermrl.evolution.selection import select
    from ermrl.experiments.baselines import random_scores
    from ermrl.ppo.config import PPOConfig

    (tmp_path / "afile").write_text("")
    cases = [
        (lambda: select(None, None, 0, 5), select, "`top` and `seeds` must be >= 1, got 0 and 5"),
        (lambda: write_video(None, tmp_path / "v.mp4", episodes=0), write_video, "`episodes` must be >= 1, got 0"),
        (lambda: random_scores("CartPole-v1", episodes=0), random_scores, "`episodes` must be >= 1, got 0"),
        (lambda: PPOConfig(use_sde=True).check_actions("CartPole-v1", True), PPOConfig,
         "`use_sde` needs continuous (Box) actions; CartPole-v1's actions are discrete"),
        (lambda: check_logdir(tmp_path / "afile"), None,
         f"`logdir` {tmp_path / 'afile'} is a file, not a folder; give a folder path (it is created if missing)"),
    ]
    for make, owner, message in cases:
        e = _raised(make)
        assert (str(e), e.owner) == (message, owner)
    e = _raised(lambda: envs.resolve_backend("LunarLander-v3", "jax"))
    assert str(e).startswith("env 'LunarLander-v3' has no JAX version; use `backend` host or auto (the JAX backend ")
    assert e.owner is envs.resolve_backend


# -- the command line's view of them ---------------------------------------------------------------------


def _parser(*words: str):
    """The (sub)parser of the command ``words`` (``("experiment", "run")``)."""
    from ermrl.cli import _subparser, build_parser

    return _subparser(build_parser(), list(words))


def test_the_command_line_shows_each_parameter_as_its_flag():
    from ermrl.cli.messages import cli_message
    from ermrl.evolution.config import EvolveConfig
    from ermrl.evolution.search_space import SearchSpace
    from ermrl.experiments.evaluation import TestConfig
    from ermrl.experiments.runner import TestBudget

    evolve = _parser("evolve")
    cases = [
        (ConfigError("`trials` must be >= 1, got 0", owner=EvolveConfig), evolve, "--trials must be >= 1, got 0"),
        (ConfigError("`envs` lists an env twice", owner=EvolveConfig), evolve, "--env lists an env twice"),
        # an Option's field of that owner, else the dest: `seeds` is --seeds in `ermrl test`, --test-seeds here
        (ConfigError("`seeds` must be >= 1", owner=TestConfig), _parser("test"), "--seeds must be >= 1"),
        (ConfigError("`seeds` must be >= 1", owner=TestBudget), _parser("experiment", "run"),
         "--test-seeds must be >= 1"),
        # an item of a tuple field has its own flag; the whole field, both
        (ConfigError("need 0 < `sr[0]` < `sr[1]`, `lr[1]`", owner=SearchSpace), evolve,
         "need 0 < --min-sr < --max-sr, --max-leak-rate"),
        (ConfigError("bad `sr`", owner=SearchSpace), evolve, "bad --min-sr/--max-sr"),
        # plain argparse options, by dest; flags marked as giving a parameter of another name
        (ConfigError("use `backend` host", owner=lambda backend: None), _parser("train"), "use --backend host"),
        (ConfigError("pass `storage_url`"), _parser("select"), "pass --storage/--out"),
        (ConfigError("`logdir` x is a file"), _parser("train"), "--tensorboard x is a file"),
        # the option tables, where the command has no such flag; else the name stays
        (ConfigError("lower `units` or `popsize`"), _parser("train"), "lower --units or --popsize"),
        (ConfigError("train with `save_agents` first"), _parser("analyze", "fft"), "train with --save-agents first"),
        (ConfigError("`nope` and `ermrl evolve`", owner=EvolveConfig), evolve, "`nope` and `ermrl evolve`"),
        (ConfigError("no `parameter` here"), None, "no `parameter` here"),
    ]
    for error, parser, shown in cases:
        assert cli_message(error, parser) == shown


def test_the_command_line_shows_flags_in_its_one_line(capsys):
    """The same library error, raised while the command runs, reaches stderr with the command's flag; --debug's
    traceback keeps the library's own words."""
    from ermrl.cli import main

    assert main(["evolve", "--trials", "1000000", "--debug"]) == 2
    lines = capsys.readouterr().err.splitlines()
    assert lines[-2:] == ["ermrl.errors.ConfigError: `trials` must be <= 100,000 (the paper's studies have 900), got "
                          "1000000",
                          "ermrl evolve: error: --trials must be <= 100,000 (the paper's studies have 900), got 1000000"]

"""``--config FILE.toml`` (or .yaml): default values for any option of a command, keyed by the flag's name
(``units = 50``, ``learning-rate = 1e-4``), checked against the command's own options; flags on the command line
override them. A key that names a flag of older versions (``ppo-lr``, ``ermrl-lr``, ``test-lrs``) sets the option
it is now (:func:`ermrl.cli.options.refuse_renamed`), so that config files written for those versions still load."""

from __future__ import annotations

import argparse
import difflib
from pathlib import Path

from ermrl.errors import ConfigError


def load_config_file(path: Path) -> dict:
    """The table of a TOML or YAML config file; ConfigError (one line) when it cannot be read."""
    if path.is_dir():
        raise ConfigError(f"config file {path} is a folder; give the path of a .toml or .yaml file")
    if not path.is_file():
        raise ConfigError(f"config file {path} does not exist; give the path of a .toml or .yaml file")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as e:
        raise ConfigError(f"config file {path} is not UTF-8 text (byte {e.start}); save it as UTF-8") from None
    except OSError as e:
        raise ConfigError(f"cannot read config file {path} ({e.strerror}); give a file you can read") from None
    try:
        if path.suffix == ".toml":
            import tomllib

            data = tomllib.loads(text)
        elif path.suffix in (".yaml", ".yml"):
            import yaml

            data = yaml.safe_load(text) or {}
        else:
            raise ConfigError(f"config file {path} must end in .toml, .yaml or .yml")
    except ConfigError:
        raise
    except Exception as e:  # tomllib.TOMLDecodeError, yaml.YAMLError
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise ConfigError(f"config file {path} is not valid {path.suffix[1:].upper()} ({first})") from None
    if not isinstance(data, dict):
        raise ConfigError(f"config file {path} must hold a table of option = value pairs")
    return data


def apply_config_file(parser: argparse.ArgumentParser, path: Path) -> None:
    """Sets the values of ``path`` as ``parser``'s defaults, after checking each key and type."""
    from ermrl.cli.options import Refused

    kept = [a for a in parser._actions if a.option_strings and not isinstance(a, Refused)
            and a.dest not in ("help", "config", "debug", "version")]
    actions = {a.dest: a for a in kept}  # a key names an option by its value's name (lr) or a flag (leak-rate)
    flags = {o.lstrip("-").replace("-", "_"): a.dest for a in kept for o in a.option_strings}
    renamed = {o.lstrip("-").replace("-", "_"): a.renamed for a in parser._actions
               if isinstance(a, Refused) and a.renamed for o in a.option_strings}  # older versions' flags (ppo-lr)
    values = {}
    for key, value in load_config_file(path).items():
        dest = str(key).lstrip("-").replace("-", "_")
        dest = dest if dest in actions else flags.get(dest, renamed.get(dest, dest))
        if dest not in actions:  # named by their flags: a reader knows --leak-rate, not its value's name (lr)
            names = sorted(a.option_strings[0].lstrip("-") for a in kept)
            close = difflib.get_close_matches(dest.replace("_", "-"), names, n=1, cutoff=0.75)
            hint = f"did you mean {close[0]!r}?" if close else f"options here: {', '.join(names)}"
            raise ConfigError(f"config file {path}: unknown option {key!r} for `{parser.prog}`; {hint}")
        values[dest] = _convert(actions[dest], value, path, key)
    parser.set_defaults(**values)


def _convert(action: argparse.Action, value, path: Path, key: str):
    """A config file's ``value`` for ``action``, checked and converted as argparse would the flag's words."""
    where = f"config file {path}: {key}"
    if isinstance(action, (argparse._StoreTrueAction, argparse.BooleanOptionalAction)):
        if not isinstance(value, bool):
            raise ConfigError(f"{where} must be true or false, got {value!r}")
        return value
    if isinstance(action, argparse._AppendAction):  # repeatable: a list of occurrences, or one
        one = not isinstance(value, list) or (isinstance(action.nargs, int) and not any(isinstance(v, list) for v in value))
        return [_values(action, v, where) for v in ([value] if one else value)]
    return _values(action, value, where)


def _values(action: argparse.Action, value, where: str):
    """One occurrence of a flag: a scalar, or a list for nargs '+', '*' or N."""
    n = action.nargs
    if n in ("+", "*") or isinstance(n, int):
        items = value if isinstance(value, list) else [value]
        if isinstance(n, int) and len(items) != n:
            raise ConfigError(f"{where} takes {n} values, got {value!r}")
        if n == "+" and not items:
            raise ConfigError(f"{where} takes at least one value, got an empty list")
        return [_scalar(action, item, where) for item in items]
    if isinstance(value, list):
        raise ConfigError(f"{where} takes one value, got a list {value!r}")
    return _scalar(action, value, where)


def _scalar(action: argparse.Action, item, where: str):
    need = {int: "an integer", float: "a number"}.get(action.type)
    if action.type is int and isinstance(item, float):
        raise ConfigError(f"{where} must be an integer, got {item!r}")
    if need and isinstance(item, (bool, list, dict)) or isinstance(item, (list, dict)):
        raise ConfigError(f"{where} has the wrong type: {item!r}; give {need or 'one value'}")
    if action.type is not None and not (isinstance(item, str) and item == "auto"):
        try:
            item = action.type(item)
        except (TypeError, ValueError, argparse.ArgumentTypeError) as e:
            fix = f"give {need}" if need else str(e) if isinstance(e, argparse.ArgumentTypeError) else "see --help"
            raise ConfigError(f"{where} has the wrong type: {item!r}; {fix}") from None
    if action.choices is not None and item not in action.choices:
        raise ConfigError(f"{where} must be one of {', '.join(map(str, action.choices))}, got {item!r}")
    return item

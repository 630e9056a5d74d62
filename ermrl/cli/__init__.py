"""The ``ermrl`` command line. Thin: it parses arguments (options from :mod:`ermrl.cli.options`, optionally
from a config file), builds configs and calls the library."""

from __future__ import annotations

import argparse
import os
import sys

import ermrl
from ermrl.errors import ConfigError


def build_parser() -> argparse.ArgumentParser:
    from ermrl.cli import analyze, commands, experiment, video

    parser = argparse.ArgumentParser(
        prog="ermrl", description="Evolving Reservoirs for Meta Reinforcement Learning (ER-MRL), vectorized in JAX.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    formatter = argparse.ArgumentDefaultsHelpFormatter
    commands.add_parsers(sub, formatter)
    experiment.add_parser(sub, formatter)
    analyze.add_parser(sub, formatter)
    video.add_parser(sub, formatter)
    return parser


def _subparser(parser: argparse.ArgumentParser, argv: list[str]) -> argparse.ArgumentParser | None:
    """The (sub)subparser that will parse ``argv``, to apply a config file's values to it."""
    node = parser
    for word in argv:
        if word.startswith("-"):
            break
        choices = next((a.choices for a in node._actions if isinstance(a, argparse._SubParsersAction)), None)
        if not choices or word not in choices:
            break
        node = choices[word]
    return node if node is not parser else None


def parse(argv: list[str] | None = None) -> argparse.Namespace:
    """Parses ``argv``; a ``--config FILE`` gives defaults that the other flags override."""
    from ermrl.cli import options

    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "config", None) is not None:
        options.apply_config_file(_subparser(parser, argv), args.config)
        args = parser.parse_args(argv)
    return args


def main(argv: list[str] | None = None) -> int:
    from ermrl.cli import analyze, commands, experiment, video

    argv = list(sys.argv[1:] if argv is None else argv)
    command = f"ermrl {argv[0]}" if argv and not argv[0].startswith("-") else "ermrl"
    try:
        args = parse(argv)
        command = f"ermrl {args.command}"
        if ermrl.CPU_DEVICES_ERROR:
            raise ConfigError(ermrl.CPU_DEVICES_ERROR)
        handlers = {**commands.COMMANDS, "experiment": experiment.run_command, "analyze": analyze.run_command,
                    "video": video.run_command}
        return handlers[args.command](args)
    except ConfigError as e:
        print(f"{command}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # output piped into a command that stopped reading (e.g. `| head`)
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1


if __name__ == "__main__":
    sys.exit(main())

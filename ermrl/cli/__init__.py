"""The ``ermrl`` command line. Thin: it parses arguments (options from :mod:`ermrl.cli.options`, optionally
from a config file), builds configs and calls the library."""

from __future__ import annotations

import argparse
import errno
import os
import signal
import sys
import threading
import traceback
from typing import NoReturn

import ermrl
from ermrl import compile_cache, devices
from ermrl.errors import OUT_OF_TIME, TERMINATED, ConfigError, OutOfTime, RunFailed, raise_terminated


def build_parser() -> argparse.ArgumentParser:
    from ermrl.cli import (
        analyze, commands, compare, convergence, dashboard, experiment, reproduce, test_progress, video,
    )

    parser = OneLineErrorParser(
        prog="ermrl", description="Evolving Reservoirs for Meta Reinforcement Learning (ER-MRL), vectorized in JAX.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {ermrl.__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    formatter = HelpFormatter
    commands.add_parsers(sub, formatter)
    experiment.add_parser(sub, formatter)
    reproduce.add_parser(sub, formatter)
    analyze.add_parser(sub, formatter)
    compare.add_parser(sub, formatter)
    test_progress.add_parser(sub, formatter)
    convergence.add_parser(sub, formatter)
    video.add_parser(sub, formatter)
    dashboard.add_parser(sub, formatter)
    _add_debug(parser)
    return parser


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """argparse's "(default: ...)" after each option's help, except where there is no value to show: a default of
    None (the option's text says what applies, e.g. the preset's value) or a switch that is off."""

    def _get_help_string(self, action):
        if action.default is None or action.default is False or action.default is argparse.SUPPRESS:
            return action.help
        return super()._get_help_string(action)


class OneLineErrorParser(argparse.ArgumentParser):
    """argparse's parser, whose errors (unknown flag, bad int, bad choice, missing argument) are a ConfigError:
    one line naming the problem and pointing at the command's --help, no usage block; ``main`` exits 2. A flag
    must be given whole: ``--timestep`` is refused, not read as ``--timesteps``."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def error(self, message: str):
        raise ConfigError(f"{message}; see `{self.prog} --help`")


DEBUG_HELP = "on an error, print its full traceback before the one-line message"


def _add_debug(parser: argparse.ArgumentParser) -> None:
    """Adds ``--debug`` to ``parser`` and every (sub)subparser, so that it may follow any command."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for child in {id(p): p for p in action.choices.values()}.values():
                _add_debug(child)
    parser.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help=DEBUG_HELP)


def _subparser(parser: argparse.ArgumentParser, argv: list[str]) -> argparse.ArgumentParser | None:
    """The (sub)subparser that will parse ``argv``, to apply a config file's values to it."""
    node = parser
    for word in argv:
        if word.startswith("-"):
            if node is parser:  # ermrl's own flags (--debug) take no value: the command comes after them
                continue
            break
        choices = next((a.choices for a in node._actions if isinstance(a, argparse._SubParsersAction)), None)
        if not choices or word not in choices:
            break
        node = choices[word]
    return node if node is not parser else None


def parse(argv: list[str] | None = None, parser: argparse.ArgumentParser | None = None) -> argparse.Namespace:
    """Parses ``argv`` with ``parser`` (default: :func:`build_parser`'s); a ``--config FILE`` gives defaults that
    the other flags override."""
    from ermrl.cli import config_files

    argv = list(sys.argv[1:] if argv is None else argv)
    parser = parser or build_parser()
    args = _parse_all(parser, argv)
    if getattr(args, "config", None) is not None:
        config_files.apply_config_file(_subparser(parser, argv), args.config)
        args = _parse_all(parser, argv)
    return args


def _parse_all(parser: argparse.ArgumentParser, argv: list[str]) -> argparse.Namespace:
    """``parser.parse_args(argv)``, with unknown flags reported by the (sub)command's parser, the closest
    flag named (``--popsise`` -> ``--popsize``)."""
    import difflib

    args, extra = parser.parse_known_args(argv)
    if extra:
        node = _subparser(parser, argv) or parser
        flags = [f for a in node._actions for f in a.option_strings if f.startswith("--")]
        word = next((w.split("=")[0] for w in extra if w.startswith("--")), None)
        close = difflib.get_close_matches(word, flags, n=1, cutoff=0.75) if word else []
        node.error(f"unrecognized arguments: {' '.join(extra)}" + (f" (did you mean {close[0]}?)" if close else ""))
    return args


def _write_refused(e: BaseException | None) -> str | None:
    """The system's reason when ``e`` or an exception behind it is a refused write (disk full, quota, file too
    large, read-only), as OSError or as SQLite says it; None for anything else."""
    while e is not None:
        if isinstance(e, OSError) and e.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS):
            return e.strerror + (f" ({e.filename})" if e.filename else "")
        for text in ("database or disk is full", "attempt to write a readonly database"):
            if text in str(e):
                return text
        e = e.__cause__ or e.__context__
    return None


def _damaged_storage(e: BaseException, args: argparse.Namespace | None) -> str | None:
    """The one-line error when ``e`` or an exception behind it is SQLite's "database disk image is malformed" or
    "file is not a database" (a study.db with a damaged page, found by a query after it opened), naming the
    command's storage (--storage, else the study's study.db); None for anything else."""
    from ermrl.evolution.study import damaged_database, damaged_storage_message

    reason = damaged_database(e)
    if reason is None:
        return None
    url = getattr(args, "storage", None)
    if url is None and getattr(args, "study", None) is not None:
        from ermrl.cli.common import storage_url

        try:
            url = storage_url(argparse.Namespace(study=args.study, storage=None, out=getattr(args, "out", None)))
        except Exception:  # not a study command after all
            url = None
    if url is None:
        return f"the study's storage is damaged ({reason}); restore it from a copy, or start a new study"
    return damaged_storage_message(url, reason)


def _shown(e: Exception, parser: argparse.ArgumentParser | None, argv: list[str]) -> str:
    """The message of a ConfigError or RunFailed as the command shows it: the parameters that a library message
    names (`trials`) as the flags of the command's parser (--trials); see :func:`ermrl.cli.messages.cli_message`."""
    from ermrl.cli import messages

    if parser is None:
        return str(e)
    return messages.cli_message(e, _subparser(parser, argv) or parser)


def _leave(code: int, why: str) -> NoReturn:
    """Ends the process at once after Ctrl-C or SIGTERM, once a worker gave its trials back: XLA's threads may
    still be running a computation, and the interpreter's teardown races them (seen as "pure virtual method called",
    SIGABRT or SIGSEGV instead of the exit status a scheduler expects)."""
    print(why, file=sys.stderr)
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def _stopped_by(e: BaseException) -> tuple[int, str] | None:
    """The exit status and line of the stop that ``e`` replaced, if it was raised while Ctrl-C or SIGTERM unwound
    the command (e.g. ``ZipFile.close`` refusing to close over a write handle that SIGTERM left open), else None."""
    seen: set[int] = set()
    cause: BaseException | None = e
    while cause is not None and id(cause) not in seen:
        seen.add(id(cause))
        if isinstance(cause, KeyboardInterrupt):
            return 130, "interrupted"
        if isinstance(cause, SystemExit) and cause.code == TERMINATED:
            return TERMINATED, "terminated (SIGTERM)"
        cause = cause.__cause__ or cause.__context__
    return None


def main(argv: list[str] | None = None) -> int:
    """Runs the command ``argv`` (default: the process's arguments) and returns its exit status. While it runs,
    SIGTERM (where nothing else handles it) stops it as Ctrl-C does: what it had half-written is removed, and it
    ends with one line and exit status 143."""
    own = threading.current_thread() is threading.main_thread() and signal.getsignal(signal.SIGTERM) == signal.SIG_DFL
    if own:
        signal.signal(signal.SIGTERM, raise_terminated)
    try:
        return _run(argv)
    finally:
        if own:
            signal.signal(signal.SIGTERM, signal.SIG_DFL)


def _run(argv: list[str] | None) -> int:
    from ermrl.cli import (
        analyze, commands, compare, convergence, dashboard, experiment, reproduce, test_progress, video,
    )

    argv = list(sys.argv[1:] if argv is None else argv)
    handlers = {**commands.COMMANDS, "experiment": experiment.run_command, "reproduce": reproduce.cmd_reproduce,
                "analyze": analyze.run_command, "compare": compare.cmd_compare,
                "test-progress": test_progress.cmd_test_progress, "convergence": convergence.cmd_convergence,
                "video": video.run_command, "dashboard": dashboard.run_command}
    words = [a for a in argv if not a.startswith("-")]
    command = f"ermrl {words[0]}" if words and words[0] in handlers else "ermrl"
    debug = "--debug" in argv  # known before parsing, so that parse errors honour it too
    parser = None
    try:
        parser = build_parser()
        args = parse(argv, parser)
        command = f"ermrl {args.command}"
        devices.setup()  # one JAX CPU device per core, or a one-line error for a bad ERMRL_CPU_DEVICES
        compile_cache.enable()  # a second run of the same shapes reads its programs back instead of compiling
        return handlers[args.command](args)
    except (ConfigError, RunFailed) as e:
        if debug:
            traceback.print_exc()
        print(f"{command}: error: {_shown(e, parser, argv)}", file=sys.stderr)
        return 2 if isinstance(e, ConfigError) else 1
    except OutOfTime as e:
        print(f"{command}: {e}", flush=True)
        return OUT_OF_TIME
    except KeyboardInterrupt:
        _leave(130, "interrupted")
    except SystemExit as e:
        if e.code != TERMINATED:  # argparse's --help and usage errors
            raise
        _leave(e.code, "terminated (SIGTERM)")
    except BrokenPipeError:  # output piped into a command that stopped reading (e.g. `| head`)
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
    except Exception as e:  # a bug, or the system failing (disk full, ...): one line unless --debug
        if (stop := _stopped_by(e)) is not None:  # a library's clean-up replaced Ctrl-C or SIGTERM with its error
            _leave(*stop)
        if debug:
            traceback.print_exc()
        if (message := _damaged_storage(e, locals().get("args"))) is not None:  # bad input: a damaged study.db
            print(f"{command}: error: {message}", file=sys.stderr)
            return 2
        if (reason := _write_refused(e)) is not None:
            fix = "give a path you can write" if "read" in reason.lower() else \
                "free some space or give another output path"
            print(f"{command}: error: {reason}; {fix}, then rerun (files are written whole or not at all, and a "
                  "study keeps every trial told before)", file=sys.stderr)
            return 1
        first = str(e).strip().splitlines()[0] if str(e).strip() else ""
        print(f"{command}: error: unexpected {type(e).__name__}{': ' + first if first else ''} "
              "(rerun with --debug for the traceback, and please report it)", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())

"""Library messages in the command line's words: a :class:`~ermrl.errors.ConfigError` names parameters in
backquotes ("`trials` must be >= 1"); :func:`cli_message` shows each as the flag that sets it in the command
("--trials must be >= 1"), from the one option table of :mod:`ermrl.cli.options`."""

from __future__ import annotations

import argparse
import re

from ermrl.cli import options


PARAMETER = re.compile(r"`([A-Za-z_]\w*(?:\[\d+\])?)`")
"""A parameter named in a library message: an identifier in backquotes, optionally an item of it (`sr[0]`)."""


def _long(action: argparse.Action) -> str | None:
    return next((f for f in action.option_strings if f.startswith("--")), None)


def _sets(pairs, parameter: str, owner) -> bool:
    """Whether (owner, parameter) ``pairs`` set ``parameter`` (an item of it too: ``sr`` for ``sr[0]``) of
    ``owner``; a pair without owner sets that parameter of any, and a message without owner means any."""
    return any((p == parameter or p.startswith(parameter + "[")) and (o is None or owner is None or o is owner)
               for o, p in pairs)


def cli_message(error: BaseException, parser: argparse.ArgumentParser | None = None) -> str:
    """``str(error)`` as the command line shows it: each parameter that the library's message names in backquotes
    replaced by the flag that sets it in this command ("`trials` must be >= 1" -> "--trials must be >= 1").

    ``error``: an exception whose ``owner`` attribute, where it has one (:class:`~ermrl.errors.ConfigError`), is
    the dataclass or function whose parameters the message names. ``parser``: the command's (sub)parser, whose
    flags are looked at first (None: the option tables only). Returns a str, one line as the message is.

    A name becomes, in this order:

    1. the command's flags that set that parameter of the owner (an :class:`~ermrl.cli.options.Option` of its
       field, or a flag marked by :func:`~ermrl.cli.options.sets`), joined by '/' when there are several (``sr``: --min-sr/--max-sr);
    2. else the command's flag whose dest is the name, if exactly one (``--backend``, ``--seeds``);
    3. else the flag of the option tables, any command's, that sets it (the owner's field; without owner, a
       field or dest of that name), if exactly one (``popsize`` in a memory estimate of ``ermrl train``);
    4. else it stays as it is, in backquotes.
    """
    owner = getattr(error, "owner", None)
    actions = parser._actions if parser is not None else []
    table = None

    def flag(match: re.Match) -> str:
        nonlocal table
        name = match.group(1)
        flags = [_long(a) for a in actions if _sets(getattr(a, options.GIVES, ()), name, owner) and _long(a)]
        if flags:
            return "/".join(dict.fromkeys(flags))
        by_dest = {_long(a) for a in actions if a.dest == name and _long(a)}
        if len(by_dest) == 1:
            return by_dest.pop()
        table = table if table is not None else [o for group in options._groups().values() for o in group]
        found = {o.flag for o in table if o.parameter is not None and _sets([(o.owner, o.parameter)], name, owner)
                 or owner is None and o.dest == name}
        return found.pop() if len(found) == 1 else match.group(0)

    return PARAMETER.sub(flag, str(error))

"""The exception types the CLI turns into one-line messages: bad user input (exit code 2), a run that cannot
go on for a reason that is not a bug (exit code 1), and a run that stopped before its time limit with work left
(exit code 75)."""

from __future__ import annotations

from typing import Callable


TERMINATED = 143
"""The exit status of a command stopped by SIGTERM (128 + 15, as a shell reports a process killed by it)."""


def raise_terminated(signum, frame) -> None:
    """A SIGTERM handler: SIGTERM as ``SystemExit(TERMINATED)``, so that the ``finally`` blocks run (a temporary
    file or a staging folder removed, nothing half-written) before the command ends with exit status 143."""
    raise SystemExit(TERMINATED)


class ConfigError(ValueError):
    """Bad input from the user (unknown env id, bad bounds, bad storage URL, ...).

    The message is one line that names the problem and the fix. It names a parameter by the library's own name,
    the dataclass field or function argument, in backquotes, and ``owner`` is the dataclass or function whose
    parameters those are (None where the message names parameters of several, or none)::

        raise ConfigError(f"`trials` must be <= 100,000, got {self.trials}", owner=type(self))

    A library user reads "`trials` must be ..."; the command line shows each backquoted name as the flag that
    sets it, "--trials must be ..." (:func:`ermrl.cli.messages.cli_message`). ``sr[0]`` names an item of a tuple
    field (the lower bound of ``sr``), whose flag may be another (``--min-sr``).
    """

    def __init__(self, *args, owner: type | Callable | None = None):
        super().__init__(*args)
        self.owner = owner


class RunFailed(RuntimeError):
    """A run that stopped for a known reason that is not a bug (e.g. every trial of several batches diverged).

    The message is one line that says what happened and where to look; what was done before is kept.
    """


OUT_OF_TIME = 75
"""The exit status of a command that stopped cleanly before its ``--stop-after`` time ran out, with work left
(``EX_TEMPFAIL`` of sysexits.h: rerun it to continue)."""


class OutOfTime(Exception):
    """A run that stopped cleanly, between two generations, because the next one would not end before its time
    limit (``--stop-after``): nothing half-trained is left, and rerunning the same command continues it. The
    message is one line that says where it stopped and how to go on; the CLI prints it and exits with
    :data:`OUT_OF_TIME`."""

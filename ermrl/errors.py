"""The exception types the CLI turns into one-line messages: bad user input (exit code 2) and a run that cannot
go on for a reason that is not a bug (exit code 1)."""


TERMINATED = 143
"""The exit status of a command stopped by SIGTERM (128 + 15, as a shell reports a process killed by it)."""


def raise_terminated(signum, frame) -> None:
    """A SIGTERM handler: SIGTERM as ``SystemExit(TERMINATED)``, so that the ``finally`` blocks run (a temporary
    file or a staging folder removed, nothing half-written) before the command ends with exit status 143."""
    raise SystemExit(TERMINATED)


class ConfigError(ValueError):
    """Bad input from the user (unknown env id, bad bounds, bad storage URL, ...).

    The message is one line that names the problem and the fix.
    """


class RunFailed(RuntimeError):
    """A run that stopped for a known reason that is not a bug (e.g. every trial of several batches diverged).

    The message is one line that says what happened and where to look; what was done before is kept.
    """

"""The one exception type for bad user input; the CLI turns it into a one-line message and exit code 2."""


class ConfigError(ValueError):
    """Bad input from the user (unknown env id, bad bounds, bad storage URL, ...).

    The message is one line that names the problem and the fix.
    """

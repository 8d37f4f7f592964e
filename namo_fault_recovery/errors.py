"""Exceptions raised by the numerical core, and the bounded text of a bad value; free of ROS."""

MAX_REASON = 200           # characters of a rejected value kept in a reason

# The exit codes of every command and node (one place, so that they cannot drift apart).
EXIT_FAILURE = 1           # something failed: a node unreachable, a benchmark that missed
EXIT_CONFIG = 1            # a node's configuration was refused (it says why on one line)
EXIT_USAGE = 2             # bad command-line arguments


class ConfigError(ValueError):
    """
    A configuration file is missing, unreadable or invalid.

    The message always names the file and the offending key, so that a robot team can
    fix the file without reading code.
    """

    def __init__(self, file, key, problem):
        self.file = str(file) if file is not None else '<memory>'
        self.key = key
        self.problem = problem
        where = f"{self.file}: key '{key}'" if key else self.file
        super().__init__(f'{where}: {problem}')


def shorten(value: object, limit: int = MAX_REASON) -> str:
    """Return ``repr``-free text of at most ``limit`` characters (a bad value stays bounded)."""
    text = str(value)
    if len(text) <= limit:
        return text
    return f'{text[:limit]}... ({len(text)} characters)'


class ReportedError(Exception):
    """
    A failure that a command reports on one line; ``code`` is its exit code.

    1 when something failed (a node unreachable, a benchmark that could not run), 2 for
    bad arguments.  The command line prints the message and exits with the code.
    """

    def __init__(self, message, code=EXIT_FAILURE):
        super().__init__(message)
        self.code = code

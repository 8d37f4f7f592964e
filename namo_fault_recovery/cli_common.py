"""What every ``namo-recovery`` subcommand shares: the one-line usage error."""

import argparse


class UsageError(Exception):
    """A bad command-line value; reported on one line with exit code 2."""


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser whose errors become UsageError instead of exiting."""

    def error(self, message):
        raise UsageError(message)

"""Errors the command line turns into one line on stderr and exit code 2.

:class:`UsageError` is bad command-line input that argparse cannot catch; a bad rig, scenario,
profile or observations file raises :class:`omnijax.config.ConfigError` (or a subclass).
"""


class UsageError(ValueError):
    """Bad command-line input that argparse cannot catch (one-line message, exit 2)."""

"""The ``omnijax`` command line: :func:`main`, and one module per subcommand (``add_parser``, ``run``)."""

from ._main import build_parser as build_parser, console as console, main as main

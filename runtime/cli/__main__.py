"""``python -m runtime.cli``: the ``omnijax`` command."""

from runtime.cli._main import console

console()

"""``python -m runtime.cli``: the ``omnijax`` command."""

import sys

from runtime.cli._main import main

sys.exit(main())

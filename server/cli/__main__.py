"""``python -m server.cli``: the ``pendant`` command."""

import sys

from server.cli.main import main

sys.exit(main())

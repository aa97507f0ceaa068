"""``python -m controller_server.cli``: the ``poise`` command."""

import sys

from controller_server.cli import main

sys.exit(main())

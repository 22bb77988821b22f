"""``python -m agents.cli``: the ``deck-landing`` command."""

import sys

from agents.cli import main

sys.exit(main())

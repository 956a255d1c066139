"""``python -m drt``: see ``drt.cli``."""

import sys

from .cli import main

sys.exit(main())

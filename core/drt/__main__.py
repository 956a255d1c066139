"""``python -m drt``: see ``drt.cli``."""

from .cli import run

run()

"""``python -m ple.cli``: the same as the ``ple`` command."""

from .main import run

run()

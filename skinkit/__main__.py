"""``python -m skinkit``: the ``skinkit`` command line."""

from skinkit.cli import main

main()

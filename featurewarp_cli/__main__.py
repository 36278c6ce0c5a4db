"""``python -m featurewarp_cli``: the same as the ``featurewarp`` command."""

from .cli import main

main()

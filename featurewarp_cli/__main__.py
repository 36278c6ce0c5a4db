"""``python -m featurewarp_cli``: the same as the ``featurewarp`` command."""

from .cli.main import main

main()

"""``python -m wearpose.cli`` = the ``wearpose`` command."""

from wearpose.cli import main

main()

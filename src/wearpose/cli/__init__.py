"""The ``wearpose`` command: thin; every subcommand calls one library function."""

from wearpose.cli.app import app, main

__all__ = ["app", "main"]

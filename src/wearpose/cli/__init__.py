"""The ``wearpose`` command: thin; every subcommand calls one library function.

Core commands live in :mod:`wearpose.cli.app`; each further command group lives in its own
``cmd_<name>.py`` module that registers itself on ``app`` when imported (discovered here), so
features can add commands without editing one shared file.
"""

import importlib
import pkgutil

from wearpose.cli.app import app, main
from wearpose.cli.helptext import reflow_app

for _m in pkgutil.iter_modules(__path__):
    if _m.name.startswith("cmd_"):
        importlib.import_module(f"{__name__}.{_m.name}")

# After every command is registered: docstrings wrapped at 100 columns print cleanly at 80.
reflow_app(app)

__all__ = ["app", "main"]

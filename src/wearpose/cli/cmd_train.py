"""``wearpose train <method>``: train an estimator on simulated sensors from the prepared corpus.

One command per declared method, generated from its declaration
(:class:`wearpose.estimators.method.MethodSpec`, ``training``): the options every method shares
(:data:`~wearpose.estimators.method.SHARED_OPTIONS`: ``--config``, ``--epochs``, ``--out``,
``--resume``, ``--threads``, ``--device``, ``--limit``, ``--checkpoint-every``, ``--json``) and
the method's own, the help text and examples, the line printed when done. The commands are
made when ``train`` is listed or run, so a method registered after import (a plug-in's entry
point, a test's :func:`~wearpose.estimators.registry.register_method`) has its command too.
Every ``wearpose train`` command runs unchanged under ``torchrun`` (DistributedDataParallel,
see :mod:`wearpose.estimators.train`).
"""

from __future__ import annotations

import inspect
import shlex
import sys
from typing import TYPE_CHECKING, Any, Optional

import click
import typer
from typer.core import TyperGroup

from wearpose.cli.app import _emit, app, console
from wearpose.cli.helptext import reflow

if TYPE_CHECKING:
    from wearpose.estimators.method import TrainOption, Training


class MethodCommands(TyperGroup):
    """The ``train`` group: a command for every declared training (a method's own and its
    further ones, :meth:`~wearpose.estimators.method.MethodSpec.training_commands`)."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        from wearpose.estimators.registry import list_trainings

        return sorted(set(super().list_commands(ctx)) | set(list_trainings()))

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        from wearpose.estimators.registry import list_trainings

        cmd = super().get_command(ctx, cmd_name)
        trainings = list_trainings() if cmd is None else {}
        if cmd_name in trainings:
            cmd = training_command(cmd_name, trainings[cmd_name])
        return cmd


train_app = typer.Typer(cls=MethodCommands,
                        help="Train an estimator on simulated sensors from the prepared corpus "
                             "(one command per method; each runs unchanged under torchrun).\n\n"
                             "Example: wearpose train empose --config tiny --threads 1 --out runs/empose_tiny",
                        no_args_is_help=True)
app.add_typer(train_app, name="train")


def _parameter(o: TrainOption) -> inspect.Parameter:
    """A typer option for the declared ``o``."""
    bounds = {k: v for k, v in (("min", o.min), ("max", o.max)) if v is not None}
    kind = o.value_type
    return inspect.Parameter(o.name, inspect.Parameter.KEYWORD_ONLY,
                             default=typer.Option(o.default, *o.option_flags, help=o.help, **bounds),
                             annotation=Optional[kind] if o.default is None else kind)


def training_command(name: str, training: Training) -> click.Command:
    """``wearpose train <name>``: the declared options parsed, the training entry called
    with them (:meth:`~wearpose.estimators.method.Training.run_options`), the result printed
    (the declaration's ``done`` line, or JSON with ``--json``). An option value the method
    refuses (:class:`~wearpose.estimators.method.OptionError`) is that option's usage error."""
    from wearpose.estimators.method import OptionError, resolve

    params = [_parameter(o) for o in training.all_options()]

    def command(**values: Any) -> None:
        own, run = training.run_options(values)
        as_json = bool(values.get("as_json"))
        run = type(run)(**{**run.__dict__, "train_command": "wearpose " + " ".join(shlex.quote(a) for a in sys.argv[1:]),
                           "quiet": as_json, "console": None if as_json else console})
        try:
            res = resolve(training.entry)(own, run)
        except OptionError as exc:
            raise typer.BadParameter(str(exc), param_hint=exc.option) from None
        _emit(res, as_json, lambda r: console.print(training.done.format(**r)))

    command.__signature__ = inspect.Signature(params)  # type: ignore[attr-defined]
    command.__annotations__ = {p.name: p.annotation for p in params}
    command.__doc__ = reflow(training.doc)  # the same paragraph joining as every other command's help
    command.__name__ = f"train_{name.replace('-', '_')}"
    one = typer.Typer(add_completion=False)
    one.command(name)(command)
    return typer.main.get_command(one)

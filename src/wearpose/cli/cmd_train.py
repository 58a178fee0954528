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
from pathlib import Path
from typing import TYPE_CHECKING, Any, Optional

import click
import typer
from typer.core import TyperGroup

from wearpose.cli.app import _emit, app, console
from wearpose.cli.helptext import reflow
from wearpose.errors import WearposeError
from wearpose.estimators.method import OptionError, resolve

if TYPE_CHECKING:
    from wearpose.estimators.method import TrainOption, Training


class MethodCommands(TyperGroup):
    """The ``train`` group: a command for every declared training (a method's own and its
    further ones, :meth:`~wearpose.estimators.method.MethodSpec.training_commands`)."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        from wearpose.estimators.registry import list_trainings  # start-up: wearpose.estimators.registry adds ~25 ms to wearpose --help

        return sorted(set(super().list_commands(ctx)) | set(list_trainings()))

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        from wearpose.estimators.registry import list_trainings  # start-up: wearpose.estimators.registry adds ~25 ms to wearpose --help

        cmd = super().get_command(ctx, cmd_name)
        trainings = list_trainings() if cmd is None else {}
        if cmd_name in trainings:
            cmd = training_command(cmd_name, trainings[cmd_name])
        return cmd


train_app = typer.Typer(cls=MethodCommands,
                        help="Train an estimator on simulated sensors from the prepared corpus "
                             "(one command per method; each runs unchanged under torchrun), or run a "
                             "recipe.\n\n"
                             "Example: wearpose train empose --config tiny --threads 1 --out runs/empose_tiny\n\n"
                             "Example: wearpose train --recipe miposer_cpu",
                        no_args_is_help=True)
app.add_typer(train_app, name="train")


def _parameter(o: TrainOption) -> inspect.Parameter:
    """A typer option for the declared ``o``."""
    bounds = {k: v for k, v in (("min", o.min), ("max", o.max)) if v is not None}
    kind = o.value_type
    return inspect.Parameter(o.name, inspect.Parameter.KEYWORD_ONLY,
                             default=typer.Option(o.default, *o.option_flags, help=o.help, **bounds),
                             annotation=Optional[kind] if o.default is None else kind)


def run_training(training: Training, values: dict[str, Any], train_command: str,
                 recipe: Any = None) -> dict[str, Any]:
    """Call ``training``'s entry with the parsed option ``values`` (every declared option by
    keyword name, ``as_json`` too) and print the result; ``recipe`` (a
    :class:`~wearpose.estimators.recipe.Recipe`) is recorded in the run's checkpoints and its
    seed checked against the run's config. A refused value is that option's usage error."""

    own, run = training.run_options(values)
    as_json = bool(values.get("as_json"))
    run = type(run)(**{**run.__dict__, "train_command": train_command, "quiet": as_json,
                       "console": None if as_json else console,
                       "recipe": recipe.record() if recipe is not None else None})
    try:
        res = resolve(training.entry)(own, run)
    except OptionError as exc:
        raise typer.BadParameter(str(exc), param_hint=exc.option) from None
    if recipe is not None:
        from wearpose.estimators.recipe import check_seed  # start-up: wearpose.estimators.recipe adds ~30 ms to wearpose --help

        check_seed(recipe, res.get("config"))
        res["recipe"] = recipe.record()
    _emit(res, as_json, lambda r: console.print(training.done.format(**r)))
    return res


@train_app.callback(invoke_without_command=True)
def train_recipe(
    ctx: typer.Context,
    recipe: Optional[str] = typer.Option(None, "--recipe", help="Run a recipe: the name of a shipped one "
                                                                "(miposer_cpu, empose12_smoke, ...) or a YAML file."),
    out: Optional[Path] = typer.Option(None, "--out", help="With --recipe: run directory (default: the recipe's "
                                                           "out option, else runs/<recipe name>)."),
    as_json: bool = typer.Option(False, "--json", help="With --recipe: print the result as JSON."),
    resume: bool = typer.Option(False, "--resume", help="With --recipe: continue the run in --out from its last "
                                                        "checkpoint (a run stopped part-way)."),
) -> None:
    """Train an estimator: `wearpose train <method> [options]`, or `wearpose train --recipe NAME`
    (one YAML file: method, every option, budget, augmentation, seed, corpus; docs/recipes.md)."""
    if ctx.invoked_subcommand is not None:
        if recipe is not None or out is not None or as_json or resume:
            raise typer.BadParameter("--recipe/--out/--json/--resume before the method: give either a recipe or "
                                     f"`wearpose train {ctx.invoked_subcommand} [options]`", param_hint="--recipe")
        return
    if recipe is None:
        console.print(ctx.get_help())
        raise typer.Exit(0)
    from wearpose.estimators.recipe import check_corpus, load_recipe, training_for  # start-up: wearpose.estimators.recipe adds ~30 ms to wearpose --help

    try:
        r = load_recipe(recipe)
    except WearposeError as exc:
        raise typer.BadParameter(str(exc), param_hint="--recipe") from None
    if r.corpus is not None:
        from wearpose.motion import CorpusStore  # start-up: wearpose.motion loads torch, +1.7 s to wearpose --help

        check_corpus(r, CorpusStore().provenance().get("corpus"))
    values = {**r.values, "as_json": as_json, "resume": resume or bool(r.values.get("resume")),
              "out": out if out is not None else (r.values.get("out") or Path("runs") / r.name)}
    training = training_for(r.method, r.path)
    run_training(training, values, f"wearpose train --recipe {shlex.quote(str(recipe))}" + (" --resume" if resume else ""),
                 recipe=r)


def training_command(name: str, training: Training) -> click.Command:
    """``wearpose train <name>``: the declared options parsed, the training entry called
    with them (:meth:`~wearpose.estimators.method.Training.run_options`), the result printed
    (the declaration's ``done`` line, or JSON with ``--json``). An option value the method
    refuses (:class:`~wearpose.estimators.method.OptionError`) is that option's usage error."""
    params = [_parameter(o) for o in training.all_options()]

    def command(**values: Any) -> None:
        run_training(training, values, "wearpose " + " ".join(shlex.quote(a) for a in sys.argv[1:]))

    command.__signature__ = inspect.Signature(params)  # type: ignore[attr-defined]
    command.__annotations__ = {p.name: p.annotation for p in params}
    command.__doc__ = reflow(training.doc)  # the same paragraph joining as every other command's help
    command.__name__ = f"train_{name.replace('-', '_')}"
    one = typer.Typer(add_completion=False)
    one.command(name)(command)
    return typer.main.get_command(one)

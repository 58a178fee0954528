"""One declaration per method: :class:`MethodSpec`.

Every method's subpackage (``estimators/<method>/__init__.py``) declares itself once as
``METHOD = MethodSpec(...)``: its estimator classes (with the baselines it ships), config class
and presets, kits, training entry with its ``wearpose train <method>`` options, demos and
evaluation protocols. The registry (:mod:`wearpose.estimators.registry`) reads the declarations;
the command line builds ``wearpose train <method>`` from them (the options every method shares,
:data:`SHARED_OPTIONS`, are declared here once), ``wearpose evaluate`` picks each model's
protocol from them and ``wearpose demo --kit`` its demo. Adding a method is adding one
subpackage with one declaration (``docs/contributing.md``, "Adding a method").

Everything a declaration names is a ``"module:attribute"`` string, imported only when used
(:func:`resolve`): reading the declarations imports no network, no corpus code and nothing of
a higher layer (demos live in ``wearpose.viewer.demos``; they are named here and imported by
the command line that runs them). This module imports only :mod:`wearpose.errors`.
"""

from __future__ import annotations

import importlib
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Mapping

from wearpose.errors import ConfigError
import importlib.util

#: ``--config tiny`` is a smoke test: it trains on this many clips unless ``--limit`` says
#: otherwise (on the whole train split its 2 epochs took over 500 s).
TINY_TRAIN_CLIPS = 8


class OptionError(ConfigError):
    """A ``wearpose train`` option value a method refuses; ``option`` names it (``"--model"``),
    so the command line reports it as that option's error."""

    def __init__(self, option: str, message: str) -> None:
        self.option = option
        super().__init__(message)


def resolve(target: str) -> Any:
    """The object a declaration names: ``"package.module:attribute"`` (imported now).

    Raises:
        ConfigError: the target is not of that form, or its module or attribute is absent.
    """
    mod, sep, attr = target.partition(":")
    if not sep or not mod or not attr:
        raise ConfigError(f"method declaration: {target!r} is not 'package.module:attribute'")
    try:
        return getattr(importlib.import_module(mod), attr)
    except (ImportError, AttributeError) as exc:
        raise ConfigError(f"method declaration: {target!r} cannot be imported ({exc})") from exc


def target_available(target: str) -> bool:
    """Whether ``target``'s module exists in this build (without importing it)."""

    try:
        return importlib.util.find_spec(target.partition(":")[0]) is not None
    except ModuleNotFoundError:  # a parent package is absent
        return False


@dataclass(frozen=True)
class TrainOption:
    """One option of ``wearpose train <method>``, declared without the command-line library
    (the CLI turns it into a typer option).

    Attributes:
        name: the keyword the training entry receives (``"batch_size"``); the option is
            ``--batch-size`` unless ``flags`` says otherwise.
        default: the default value; ``None`` makes the option optional (not given = None).
        help: one or two sentences for ``--help``.
        type: ``int``, ``float``, ``str``, ``bool`` or ``Path``; default: the default's type.
        flags: the option's names when not derived from ``name`` (``("--json",)``, or
            ``("--learned-init/--no-learned-init",)`` for an on/off pair).
        min, max: inclusive bounds of a number, checked by the command line.
    """

    name: str
    default: Any
    help: str
    type: type | None = None
    flags: tuple[str, ...] = ()
    min: float | None = None
    max: float | None = None

    @property
    def value_type(self) -> type:
        if self.type is not None:
            return self.type
        if self.default is None:
            raise ConfigError(f"train option {self.name!r}: default None needs a type")
        return type(self.default)

    @property
    def option_flags(self) -> tuple[str, ...]:
        return self.flags or ("--" + self.name.replace("_", "-"),)


#: The options every ``wearpose train <method>`` takes, declared once. A method changes a
#: default or a help text with :attr:`Training.defaults` / :attr:`Training.help`, or leaves one
#: out with :attr:`Training.omit`; what it adds is :attr:`Training.options`.
SHARED_OPTIONS: tuple[TrainOption, ...] = (
    TrainOption("config", "cpu", "Preset: tiny (smoke test: 8 training clips unless --limit, under a minute), "
                                 "cpu (CPU-sized), paper."),
    TrainOption("epochs", None, "Override the preset's number of epochs.", int),
    TrainOption("out", None, "Run directory.", Path),
    TrainOption("resume", False, "Continue from <out>/last.pt.", flags=("--resume",)),
    TrainOption("threads", None, "torch CPU threads (default: torch's choice).", int, min=1),
    TrainOption("device", "auto", "auto (CUDA when available), cpu or cuda[:i]."),
    TrainOption("limit", None, "Use only the first N training clips (quick runs).", int, min=1),
    TrainOption("source", None, "Train and validate on the clips of this source (lab) only: bandai, cmu_daz "
                                "or cmu_asf (the unseen-lab protocol: evaluate with --source of another).", str),
    TrainOption("checkpoint_every", 100, "Save last.pt every N optimiser steps (and every epoch).", min=1),
    TrainOption("as_json", False, "Print the result as JSON.", flags=("--json",)),
)

#: The options of a method whose config is a :class:`~wearpose.estimators.trainconfig.TrainConfig`
#: and whose training data go through the training mix (:attr:`Training.mix`; declared once):
#: the seed, the fine-tuning start, and the mix (TrainConfig's ``aug_*``, ``procedural_*``,
#: ``train_shapes``; docs/augmentation.md). They come after the method's own options.
MIX_OPTIONS: tuple[TrainOption, ...] = (
    TrainOption("seed", None, "Base seed of the data draws, batch order and initial weights (default: the "
                              "preset's).", int, min=0),
    TrainOption("init_from", None, "Start from this checkpoint's weights (fine-tuning: same method, kit and "
                                   "sizes; fresh optimiser).", Path),
    TrainOption("mirror", False, "Add the left/right mirror image of every training clip.", flags=("--mirror",)),
    TrainOption("speed_copies", None, "Add N copies of every training clip played faster or slower "
                                      "(0.8-1.25x, log-uniform).", int, min=0),
    TrainOption("heading_copies", None, "Add N copies of every training clip turned to a random heading.", int, min=0),
    TrainOption("mix_copies", None, "Add N copies of every training clip with the upper body of another clip.",
                int, min=0),
    TrainOption("site_jitter", None, "Strap every simulated sensor up to M metres off its site, drawn per "
                                     "training clip.", float, min=0.0, max=0.1),
    TrainOption("rest_offset", None, "Turn every joint of every training clip by a constant offset of up to DEG "
                                     "degrees, drawn per clip (another capture chain's rest pose).", float,
                min=0.0, max=45.0),
    TrainOption("rest_offset_joints", None, "The joints --rest-offset turns, comma-separated SMPL names (default: "
                                            "all), e.g. left_collar,right_collar,neck.", str),
    TrainOption("procedural", None, "Add N procedural clips of each motion family the corpus lacks (squat, kneel, "
                                    "pick up, sit, lie down, crawl, reach).", int, min=0),
    TrainOption("shapes", None, "Wearers of the training clips: corpus (the clips' own body) or random (an adult "
                                "body drawn per clip).", str),
    TrainOption("families", None, "Procedural families --procedural draws from, comma-separated (default: all "
                                  "seven); leave some out to test them as motion the model never saw.", str),
)


def _names(text: str | None) -> tuple[str, ...] | None:
    """A comma-separated option (``--families``, ``--rest-offset-joints``) as a tuple of names;
    None (not given) stays None."""
    return None if text is None else tuple(n.strip() for n in text.split(",") if n.strip())


@dataclass(frozen=True)
class TrainRun:
    """The shared options of one ``wearpose train`` run, as the training entry receives them
    (those the method omits are at their defaults); ``recipe``: the resolved recipe the run was
    started from (:meth:`wearpose.estimators.recipe.Recipe.record`), kept in the checkpoint."""

    config: str = "cpu"
    out: Path | None = None
    epochs: int | None = None
    resume: bool = False
    threads: int | None = None
    device: str = "auto"
    limit: int | None = None
    source: str | None = None
    checkpoint_every: int = 100
    seed: int | None = None
    init_from: Path | None = None
    mirror: bool = False
    speed_copies: int | None = None
    heading_copies: int | None = None
    mix_copies: int | None = None
    site_jitter: float | None = None
    rest_offset: float | None = None
    rest_offset_joints: str | None = None
    procedural: int | None = None
    shapes: str | None = None
    families: str | None = None
    train_command: str = ""
    quiet: bool = False
    console: Any = None
    recipe: Mapping[str, Any] | None = None

    def config_overrides(self) -> dict[str, Any]:
        """The config fields the shared options set: :meth:`mix_overrides` and ``epochs`` (so the
        config a checkpoint and its card keep says how long the run was, not the preset; None:
        the preset's, ``config.override`` skips them; a method without ``--epochs`` has None)."""
        return {**self.mix_overrides(), "epochs": self.epochs}

    def mix_overrides(self) -> dict[str, Any]:
        """The config fields of ``seed`` and the training mix alone (None: the preset's), for a
        config that is the mix's only (N-BEATS' :class:`~wearpose.estimators.trainconfig.TrainConfig`)."""
        return {"seed": self.seed, "aug_mirror": self.mirror or None, "aug_speed_copies": self.speed_copies,
                "aug_heading_copies": self.heading_copies, "aug_mix_copies": self.mix_copies,
                "aug_site_jitter_m": self.site_jitter, "aug_rest_offset_deg": self.rest_offset,
                "aug_rest_offset_joints": _names(self.rest_offset_joints),
                "procedural_per_family": self.procedural, "train_shapes": self.shapes,
                "procedural_families": _names(self.families)}

    @property
    def limit_train(self) -> int | None:
        """The training-clip limit: ``--limit``, else :data:`TINY_TRAIN_CLIPS` for ``tiny``."""
        return self.limit if self.limit is not None or self.config != "tiny" else TINY_TRAIN_CLIPS

    def corpus_store(self) -> Any:
        """The store the run trains on: None (the prepared corpus, each method's default), or
        with ``--source`` the prepared corpus restricted to that source
        (:meth:`wearpose.motion.CorpusStore.subset`), train and val splits alike.

        Raises:
            OptionError: ``--source`` names a source the store does not hold.
        """
        if self.source is None:
            return None
        from wearpose.motion import CorpusStore  # deferred: reading declarations loads no corpus code - start-up: motion loads torch, +1.6 s (1067 modules) to this torch-free module

        try:
            return CorpusStore().subset(self.source)
        except ConfigError as exc:
            raise OptionError("--source", str(exc)) from None

    def loop(self) -> dict[str, Any]:
        """The keyword options of :func:`wearpose.estimators.train.train_estimator` this run sets."""
        return {"epochs": self.epochs, "resume": self.resume, "threads": self.threads, "device": self.device,
                "limit_train": self.limit_train, "checkpoint_every": self.checkpoint_every,
                "train_command": self.train_command, "quiet": self.quiet, "console": self.console,
                "store": self.corpus_store(), "recipe": self.recipe, "init_from": self.init_from}


@dataclass(frozen=True)
class Training:
    """How ``wearpose train <method>`` trains the method.

    Attributes:
        entry: ``"module:function"``, called as ``fn(options, run) -> result``: ``options`` the
            method's own option values by name (:attr:`options`), ``run`` a :class:`TrainRun`;
            it builds the config and estimator, trains, and returns a JSON-able dict with at
            least ``method`` and what :attr:`done` formats. A refused option value is an
            :class:`OptionError` naming the option.
        doc: the command's help: one line, then paragraphs and ``Example: wearpose train ...``
            lines.
        done: the line printed after training, formatted with the result
            (``"done: best val MPJPE {best:.1f} mm; checkpoints in {out_dir}"``).
        options: the method's own options, in ``--help`` order (after ``--config``).
        defaults / help: the shared options' defaults and help texts this method changes.
        omit: shared options this method does not take (BiRAE: ``epochs``, ``limit``; a
            training with no presets: ``config``).
        mix: the method also takes :data:`MIX_OPTIONS` (seed, ``--init-from``, the training mix),
            passed on in :class:`TrainRun` (:meth:`TrainRun.config_overrides`).
        val_metric: the validation figure ``best.pt`` is kept by (lower is better), for a
            training outside :mod:`wearpose.estimators.train` (None: its ``train`` module's task
            says, :func:`wearpose.estimators.recipe.selection_metric`).
        reader: ``"module:function"`` reading one of its kept checkpoints as ``(weights, meta,
            data_fingerprint)``, for a training whose checkpoints are not
            :func:`~wearpose.estimators.checkpoint.save_checkpoint`'s (None: they are).
    """

    entry: str
    doc: str
    done: str
    options: tuple[TrainOption, ...] = ()
    defaults: Mapping[str, Any] = field(default_factory=dict)
    help: Mapping[str, str] = field(default_factory=dict)
    omit: frozenset[str] = frozenset()
    mix: bool = False
    val_metric: str | None = None
    reader: str | None = None

    def all_options(self) -> tuple[TrainOption, ...]:
        """``--config``, the method's options, then the other shared ones (``--json`` last)."""
        shared = {o.name: o for o in (*SHARED_OPTIONS, *(MIX_OPTIONS if self.mix else ()))}
        unknown = (set(self.defaults) | set(self.help) | set(self.omit)) - set(shared)
        if unknown:
            raise ConfigError(f"train declaration: {sorted(unknown)} are not shared options "
                              f"({', '.join(shared)})")
        own = [n for n in (o.name for o in self.options) if n in shared]
        if own:
            raise ConfigError(f"train declaration: {own} are shared options; change them with defaults/help")

        def shared_option(name: str) -> TrainOption:
            o = shared[name]
            return replace(o, default=self.defaults.get(name, o.default), help=self.help.get(name, o.help))

        rest = [shared_option(o.name) for o in SHARED_OPTIONS[1:] if o.name not in self.omit]
        mix = [shared_option(o.name) for o in MIX_OPTIONS if o.name not in self.omit] if self.mix else []
        first = () if "config" in self.omit else (shared_option("config"),)
        return (*first, *self.options, *mix, *rest)

    def run_options(self, values: Mapping[str, Any]) -> tuple[dict[str, Any], TrainRun]:
        """Split parsed option ``values`` into the method's own options and the :class:`TrainRun`
        fields (``as_json`` becomes neither: it is the command line's)."""
        shared = {o.name for o in (*SHARED_OPTIONS, *MIX_OPTIONS)} - {"as_json"}
        own = {k: v for k, v in values.items() if k not in shared and k != "as_json"}
        return own, TrainRun(**{k: v for k, v in values.items() if k in shared})


@dataclass(frozen=True)
class EstimatorEntry:
    """One estimator class a method ships (the method itself or one of its baselines).

    Attributes:
        name: the registry name (a checkpoint's ``method``).
        target: ``"module:Class"`` of the :class:`~wearpose.estimators.base.Estimator`.
        protocol: ``"module:function"`` of its evaluation protocol for one model,
            ``fn(estimator, store, split, clips, seed, noise, progress, frame_stride) -> dict``
            with ``frames``, ``clip_ids``, ``metrics`` (flat, report units, the unit in the key),
            ``per_clip`` (``[{"clip", "frames", <metric>: the clip's mean}]``, grouped by source
            and motion class by the runner), ``lead`` (the metric the breakdown table shows),
            ``protocol`` (one sentence) and ``detail`` (:func:`wearpose.evaluate.protocols.evaluate_model`).
        compare: instead, ``"module:function"`` of a protocol that compares several checkpoints
            of the method family on shared simulations (EM-POSE:
            :func:`wearpose.estimators.empose.evaluate.evaluate_models`).
        evaluated_by: where it is evaluated when ``wearpose evaluate`` has no protocol for it
            (``"python benchmarks/empose_lbfgs.py"``).
    """

    name: str
    target: str
    protocol: str | None = None
    compare: str | None = None
    evaluated_by: str | None = None


@dataclass(frozen=True)
class MethodSpec:
    """A method's one declaration (module doc).

    Attributes:
        name: the method's name: ``wearpose train <name>``; usually also its main estimator's.
        summary: one line (paper, what goes in and out).
        estimators: the estimator classes it ships.
        config: ``"module:Class"`` of its config dataclass (``preset(name)``, ``to_dict``), or None.
        presets: the config presets (``tiny`` finishes in under a minute, ``cpu`` ships).
        kits: the sensor kits it reads (:func:`wearpose.sensors.get_kit`).
        training: how ``wearpose train <name>`` trains it; None for a method with nothing to train.
        trainings: further training commands, ``wearpose train <key>``: the networks the method's
            estimators load besides their own weights or a variant trained its own way
            (EM-POSE: ``empose-twostage`` warm-started, ``poseprior`` of ``empose-lbfgs``;
            MI-Poser: ``nbeats``, MIM's trajectory forecaster).
        demos: kit -> ``"module:function"`` of ``wearpose demo --kit <kit>``
            (``fn(clip, out) -> dict``, see :mod:`wearpose.cli.demo`).
    """

    name: str
    summary: str
    estimators: tuple[EstimatorEntry, ...]
    config: str | None = None
    presets: tuple[str, ...] = ()
    kits: tuple[str, ...] = ()
    training: Training | None = None
    trainings: Mapping[str, Training] = field(default_factory=dict)
    demos: Mapping[str, str] = field(default_factory=dict)

    def training_commands(self) -> dict[str, Training]:
        """``wearpose train`` command name -> :class:`Training`: :attr:`training` under the
        method's name, then :attr:`trainings`."""
        own = {self.name: self.training} if self.training is not None else {}
        return {**own, **self.trainings}

    def estimator(self, name: str) -> EstimatorEntry:
        for e in self.estimators:
            if e.name == name:
                return e
        raise ConfigError(f"method {self.name!r} ships no estimator {name!r}; it ships "
                          f"{', '.join(e.name for e in self.estimators)}")


def finite_metrics(d: Mapping[str, Any]) -> dict[str, float]:
    """The finite numbers of ``d`` as floats (booleans, NaN, text and nested values left out):
    a protocol's flat ``metrics`` from its method's own summary."""
    return {k: float(v) for k, v in d.items() if isinstance(v, (int, float)) and not isinstance(v, bool)
            and math.isfinite(float(v))}


def lazy_exports(package: str, names: Mapping[str, str]) -> Callable[[str], Any]:
    """A module ``__getattr__`` for a method's ``__init__.py``: ``names`` maps each public name
    to the submodule defining it (``{"PipEstimator": "estimator"}``), imported on first use, so
    reading the declaration stays cheap; any other submodule is importable by attribute too."""
    def __getattr__(name: str) -> Any:
        if name in names:
            return getattr(importlib.import_module(f"{package}.{names[name]}"), name)
        if not name.startswith("__"):
            try:
                return importlib.import_module(f"{package}.{name}")
            except ModuleNotFoundError as exc:
                if exc.name != f"{package}.{name}":
                    raise
        raise AttributeError(f"module {package!r} has no attribute {name!r}")
    return __getattr__

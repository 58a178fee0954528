"""Training recipes: one YAML file holds everything a ``wearpose train`` run is made of, so
``wearpose train --recipe NAME`` reruns it.

A recipe (``format: wearpose.recipe``, ``version: 1``)::

    name: miposer_cpu                # the weights it makes (optional; default: the file's stem)
    method: miposer                  # wearpose train <method> (or another training command: nbeats)
    options: {config: cpu, model: avatarposer, wrists: 2, ...}   # the method's options
    budget: {epochs: 5}              # options that set the training length
    augmentation: {}                 # options that set the augmentation (PIP: mirror, speed_copies)
    init_from: null                  # the checkpoint the run starts from (fine-tuning): a path, or
                                     # archive:<name> for archived weights (wearpose/weights/archive;
                                     # so may any other file option, e.g. empose-twostage's init)
    seed: 0                          # the config's seed (the run's --seed; checked against its config)
    corpus: {name: data-v2, manifest_sha1: 94395d87...}   # the prepared store must hold this corpus

Every key of ``options``, ``budget`` and ``augmentation`` is an option of ``wearpose train
<method>`` by its keyword name (``batch_size``, ``checkpoint_every``; :class:`~wearpose.estimators.method.TrainOption`),
given in one section only; options a recipe leaves out take their declared defaults, and the run
records the whole resolved set. ``method`` names any ``wearpose train`` command: a method's own
training or one of its further trainings (:attr:`~wearpose.estimators.method.MethodSpec.trainings`,
e.g. MI-Poser's ``nbeats`` forecaster). The shipped recipes are
``estimators/<method>/recipes/<name>.yaml`` beside the command's training entry (found by name,
:func:`find_recipe`); any other file is given by its path.

The checkpoint records the resolved recipe (``meta["recipe"]``) and ``tools/ship_weights.py``
copies it into the weights' card.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

from wearpose.errors import ConfigError, InputFileError
from wearpose.estimators.method import Training, resolve
import yaml

FORMAT = "wearpose.recipe"
VERSION = 1
#: Sections whose keys are the method's train options.
OPTION_SECTIONS = ("options", "budget", "augmentation")
_KEYS = {"format", "version", "name", "method", "init_from", "seed", "corpus", "notes", *OPTION_SECTIONS}
_EXPECTED = (f"a YAML mapping with format: {FORMAT}, version: {VERSION}, method and options "
             "(docs/recipes.md)")


@dataclass(frozen=True)
class Recipe:
    """A loaded recipe (module doc).

    Attributes:
        path: the file; name: the weights it makes; method: the ``wearpose train`` command (a
            method's name, or a further training's such as ``nbeats``).
        values: every option of ``wearpose train <method>`` by keyword name, resolved (the
            declared defaults overridden by the recipe's sections and ``init_from``).
        seed: the config seed the run must have (None: not checked).
        corpus: ``{"name", "manifest_sha1"?}`` the prepared store must hold (None: any).
        sha1: of the file's bytes.
    """

    path: Path
    name: str
    method: str
    values: dict[str, Any]
    seed: int | None = None
    corpus: dict[str, Any] | None = None
    sha1: str = ""

    def record(self) -> dict[str, Any]:
        """What a checkpoint and a card keep of the recipe: name, file, its SHA-1, method, the
        resolved options, seed and corpus."""
        return {"name": self.name, "file": shown_path(self.path), "sha1": self.sha1, "method": self.method,
                "options": {k: (str(v) if isinstance(v, Path) else v) for k, v in self.values.items()},
                "seed": self.seed, "corpus": self.corpus}


def shown_path(path: Path) -> str:
    """``path`` as a checkpoint and card keep it: a shipped recipe relative to the installed
    package (``wearpose/estimators/<method>/recipes/<name>.yaml``, the same on every machine; the
    working copy it ran from means nothing elsewhere), any other recipe file as given."""
    package = Path(__file__).resolve().parents[2]  # the folder holding wearpose/
    try:
        return Path(path).resolve().relative_to(package).as_posix()
    except ValueError:
        return str(path)


def recipe_dirs() -> dict[str, Path]:
    """``wearpose train`` command -> its shipped recipes folder: ``recipes`` beside its training
    entry's module (``estimators/<method>/recipes``; a method's further trainings share it)."""
    from wearpose.estimators.registry import list_trainings  # start-up: registry adds ~35 ms (63 modules) to import this module

    out = {}
    for name, training in list_trainings().items():
        found = importlib.util.find_spec(training.entry.partition(":")[0])
        if found is not None and found.origin:
            out[name] = Path(found.origin).parent / "recipes"
    return out


def shipped_recipes() -> dict[str, Path]:
    """Recipe name -> file, of every shipped recipe."""
    dirs = sorted(set(recipe_dirs().values()))
    return {p.stem: p for d in dirs if d.is_dir() for p in sorted(d.glob("*.yaml"))}


def find_recipe(name_or_path: str | Path) -> Path:
    """A recipe file: an existing path, else the shipped recipe of that name.

    Raises:
        ConfigError: neither (the message lists the shipped names).
    """
    p = Path(name_or_path)
    if p.is_file():
        return p
    known = shipped_recipes()
    if str(name_or_path) in known:
        return known[str(name_or_path)]
    raise ConfigError(f"recipe {str(name_or_path)!r} is neither a file nor a shipped recipe; expected a YAML path or "
                      f"one of {', '.join(sorted(known)) or '(none shipped)'}")


def load_recipe(name_or_path: str | Path) -> Recipe:
    """Read and check a recipe (module doc) against its method's declaration.

    Raises:
        InputFileError: not YAML, not a recipe, an unknown key, method or option, an option in
            two sections, a value of the wrong type.
    """

    path = find_recipe(name_or_path)
    raw = path.read_bytes()
    try:
        d = yaml.safe_load(raw.decode("utf-8"))
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise InputFileError(path, f"not readable YAML ({exc})", _EXPECTED) from exc
    if not isinstance(d, dict) or d.get("format") != FORMAT or d.get("version") != VERSION:
        raise InputFileError(path, "not a wearpose recipe of this version", _EXPECTED, field="format/version")
    unknown = sorted(set(d) - _KEYS)
    if unknown:
        raise InputFileError(path, f"unknown keys {unknown}", f"only {', '.join(sorted(_KEYS))}", field=unknown[0])
    command, training = _training(path, d.get("method"))
    values = _values(path, d, command, training)
    seed = d.get("seed")
    if seed is not None and not isinstance(seed, int):
        raise InputFileError(path, f"seed {seed!r}", "an integer (the config's seed) or null", field="seed")
    corpus = d.get("corpus")
    if corpus is not None and not (isinstance(corpus, dict) and isinstance(corpus.get("name"), str)):
        raise InputFileError(path, f"corpus {corpus!r}", "null or a mapping with name (and manifest_sha1)", field="corpus")
    return Recipe(path=path, name=str(d.get("name") or path.stem), method=command, values=values, seed=seed,
                  corpus=corpus, sha1=hashlib.sha1(raw).hexdigest())


def training_for(name: Any, path: Path = Path("<recipe>")) -> Training:
    """The :class:`~wearpose.estimators.method.Training` of ``wearpose train <name>``.

    Raises:
        InputFileError: no such training command (naming ``path``'s ``method`` field and the
            declared commands).
    """
    return _training(path, name)[1]


def _training(path: Path, name: Any) -> tuple[str, Training]:
    from wearpose.estimators.registry import list_trainings  # start-up: registry adds ~35 ms (63 modules) to import this module

    trainings = list_trainings()
    if name not in trainings:
        raise InputFileError(path, f"method {name!r}", f"a wearpose train command: one of {', '.join(trainings)}",
                             field="method")
    return str(name), trainings[name]


def _values(path: Path, d: Mapping[str, Any], command: str, training: Training) -> dict[str, Any]:
    """The command's options: declared defaults, then the recipe's sections and ``init_from``."""
    declared = {o.name: o for o in training.all_options() if o.name != "as_json"}
    values: dict[str, Any] = {n: o.default for n, o in declared.items()}
    seen: dict[str, str] = {}
    sections = [(s, d.get(s) or {}) for s in OPTION_SECTIONS]
    if d.get("init_from") is not None:
        sections.append(("init_from", {"init_from": _archived_or_path(path, d["init_from"])}))
    if isinstance(d.get("seed"), int) and "seed" in declared:  # a bad seed is named by load_recipe
        sections.append(("seed", {"seed": d["seed"]}))
    for section, opts in sections:
        if not isinstance(opts, dict):
            raise InputFileError(path, f"{section} is {type(opts).__name__}", "a mapping of option names to values",
                                 field=section)
        for k, v in opts.items():
            if k not in declared:
                raise InputFileError(path, f"{k!r} is not an option of wearpose train {command}",
                                     f"one of {', '.join(declared)}", field=f"{section}.{k}")
            if k in seen:
                raise InputFileError(path, f"{k!r} is given in {seen[k]} and {section}", "each option once",
                                     field=f"{section}.{k}")
            seen[k] = section
            if declared[k].value_type is Path and section != "init_from":  # archive:<name> for any file option
                v = _archived_or_path(path, v, f"{section}.{k}")
            values[k] = _typed(path, f"{section}.{k}", v, declared[k].value_type)
    return values


def _archived_or_path(path: Path, v: Any, field: str = "init_from") -> Any:
    """``init_from``, or any other file option (``options.init`` of ``empose-twostage``):
    ``archive:<name>`` is archived shipped weights (:func:`wearpose.weights.archived_path`, the
    same file on every checkout); anything else a path."""
    if not (isinstance(v, str) and v.startswith("archive:")):
        return v
    from wearpose.weights import archived_path  # start-up: keeps the weights module out of reading declarations

    try:
        return str(archived_path(v.split(":", 1)[1]))
    except ConfigError as exc:
        raise InputFileError(path, str(exc), "archive:<name> of a file in wearpose/weights/archive", field=field) from None


def _typed(path: Path, where: str, v: Any, kind: type) -> Any:
    """``v`` as the option's type (a path from a string); None stays None."""
    if v is None:
        return None
    if kind is Path and isinstance(v, str):
        return Path(v)
    if kind is float and isinstance(v, int) and not isinstance(v, bool):
        return float(v)
    if not isinstance(v, kind) or (kind is int and isinstance(v, bool)):
        raise InputFileError(path, f"{v!r} is {type(v).__name__}", f"a {kind.__name__}", field=where)
    return v


def check_corpus(recipe: Recipe, provenance: Mapping[str, Any] | None) -> None:
    """Refuse a store that does not hold the recipe's corpus (name, and manifest SHA-1 when given).

    Args:
        provenance: the store's ``corpus`` record (:meth:`wearpose.motion.CorpusStore.provenance`).

    Raises:
        ConfigError: naming both corpora and the fix.
    """
    want = recipe.corpus
    if want is None:
        return
    have = dict(provenance or {})
    ok = have.get("name") == want["name"] and (not want.get("manifest_sha1")
                                              or have.get("manifest_sha1") == want["manifest_sha1"])
    if not ok:
        raise ConfigError(f"recipe {recipe.path}: made on corpus {want['name']} (manifest "
                          f"{str(want.get('manifest_sha1') or 'any')[:12]}), but the prepared store holds "
                          f"{have.get('name')} (manifest {str(have.get('manifest_sha1'))[:12]}); prepare that corpus "
                          f"(wearpose data prepare ../shared/{want['name']}) or set WEARPOSE_CACHE to a store of it")


def check_seed(recipe: Recipe, config: Mapping[str, Any] | None) -> None:
    """Refuse a run whose config seed is not the recipe's (the preset changed since).

    Raises:
        ConfigError: naming the recipe, both seeds and the fix.
    """
    if recipe.seed is None or config is None or "seed" not in config:
        return
    if int(config["seed"]) != recipe.seed:
        raise ConfigError(f"recipe {recipe.path}: seed {recipe.seed}, but the run's config has seed {config['seed']}; "
                          "the preset changed since the recipe was written: update the recipe's seed or the preset")


def selection_metric(method: str) -> str:
    """The validation figure ``wearpose train <method>`` keeps ``best.pt`` by (lower is better):
    the training's declared ``val_metric``, else the ``val_metric`` of the training task in the
    ``train`` module beside its training entry (every trainable method's package has one)."""
    training = training_for(method)
    if training.val_metric is not None:
        return training.val_metric
    mod = importlib.import_module(training.entry.split(":")[0].rsplit(".", 1)[0] + ".train")
    found = {c.val_metric for c in vars(mod).values() if isinstance(c, type) and c.__module__ == mod.__name__
             and isinstance(getattr(c, "val_metric", None), str)}
    if len(found) != 1:
        raise ConfigError(f"{mod.__name__}: expected one training task with a val_metric, found {sorted(found)}")
    return found.pop()


def _kept(training: Training, path: str | Path) -> tuple[Mapping[str, Any], Mapping[str, Any], str]:
    """A kept checkpoint of ``training`` as ``(weights, meta, data_fingerprint)``: its declared
    reader, else :func:`~wearpose.estimators.checkpoint.load_checkpoint`."""
    if training.reader is not None:
        return resolve(training.reader)(path)
    from wearpose.estimators.checkpoint import load_checkpoint  # start-up: torch only when comparing

    ck = load_checkpoint(path)
    return ck.weights, ck.meta, ck.data_fingerprint


def reproduction(recipe: str | Path, rerun: str | Path, reference: str | Path, tolerance: float = 0.02) -> dict[str, Any]:
    """Does a rerun of ``recipe`` reproduce ``reference`` (the weights it made, or an earlier run's
    kept checkpoint)? Compares the validation figures both kept checkpoints recorded (``meta``:
    every numeric ``val_*``, relative difference to the reference), the largest absolute
    difference between their weights (0: bit-identical; None: different tensor sets) and their
    data fingerprints. ``passes``: the method's :func:`selection_metric` within ``tolerance``."""
    r = load_recipe(recipe)
    training = training_for(r.method, r.path)
    (wa, ma, fa), (wb, mb, fb) = _kept(training, rerun), _kept(training, reference)
    key = selection_metric(r.method)
    num = lambda m, k: isinstance(m.get(k), (int, float)) and not isinstance(m.get(k), bool)  # noqa: E731
    figures = {k: {"rerun": ma[k], "reference": mb[k], "relative": (ma[k] - mb[k]) / abs(mb[k]) if mb[k] else None}
               for k in sorted(set(ma) & set(mb)) if k.startswith("val_") and num(ma, k) and num(mb, k)}
    same = set(wa) == set(wb) and all(wa[k].shape == wb[k].shape for k in wa)
    diff = max((float((wa[k].double() - wb[k].double()).abs().max()) for k in wa if wa[k].numel()),
               default=0.0) if same else None
    head = figures.get(key, {}).get("relative")
    return {"recipe": r.name, "method": r.method, "recipe_sha1": r.sha1, "rerun": str(rerun), "reference": str(reference),
            "epoch": {"rerun": ma.get("epoch"), "reference": mb.get("epoch")}, "headline": key,
            "figures": figures, "passes": head is not None and abs(head) <= tolerance,
            "max_abs_weight_difference": diff, "same_data": fa == fb}


__all__ = ["Recipe", "load_recipe", "shown_path", "find_recipe", "shipped_recipes", "recipe_dirs", "check_corpus",
           "check_seed", "selection_metric", "reproduction", "training_for", "FORMAT", "VERSION"]

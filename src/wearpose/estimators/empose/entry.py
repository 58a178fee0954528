"""EM-POSE's training entry for ``wearpose train empose`` (its declaration:
:data:`wearpose.estimators.empose.METHOD`): options -> config -> estimator -> training run."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

from wearpose.errors import ConfigError
from wearpose.estimators.method import OptionError, TrainRun

#: ``--model`` values: the LGD-RNN, the Table 2 baselines and the two-stage model.
MODELS = ("lgd", "resnet", "birnn", "twostage")


def train_from_options(opts: Mapping[str, Any], run: TrainRun) -> dict[str, Any]:
    """Train the ``--model`` network for ``--sensors`` EM sensors (kit em12 / em6) with the
    ``--config`` preset, overridden by the options given, optionally as a Table 3 ablation.

    Returns:
        :func:`~wearpose.estimators.empose.train.train_empose`'s result with ``method``,
        ``model``, ``sensors`` and ``config`` (the config as a dict).
    """
    from wearpose.estimators.empose.baselines import baseline_config, estimator_class  # start-up: the empose modules load torch, +5.1 s (1111 modules) to import this entry
    from wearpose.estimators.empose.config import ablation_config  # start-up: the empose modules load torch, +5.1 s (1111 modules) to import this entry
    from wearpose.estimators.empose.train import train_empose  # start-up: the empose modules load torch, +5.1 s (1111 modules) to import this entry

    model, sensors, ablation = opts["model"], opts["sensors"], opts["ablation"]
    if model not in MODELS:
        raise OptionError("--model", f"unknown model {model!r}; expected lgd, resnet, birnn or twostage")
    if opts["offsets"] not in (None, "random", "none"):
        raise OptionError("--offsets", f"expected random or none, got {opts['offsets']!r}")
    own = ("hidden", "width", "iterations", "batch_size", "offsets", "lr", "lambda_shape")
    cfg = baseline_config(run.config, sensors, model).override(**{k: opts[k] for k in own}, **run.config_overrides())
    if ablation is not None:
        if model != "lgd":
            raise OptionError("--ablation", f"ablations are of the LGD-RNN; got --model {model}")
        try:
            cfg = ablation_config(cfg, ablation)
        except ConfigError as exc:  # names the unknown row and the known ones
            raise OptionError("--ablation", str(exc)) from None
    out = run.out or Path("runs") / f"{'empose' if model == 'lgd' else model}{sensors}_{run.config}"
    res = train_empose(estimator_class(model)(cfg), out, **run.loop())
    return {"method": "empose", "model": model, "sensors": sensors, "config": cfg.to_dict(), **res}

"""Shipped weights of the estimators on :class:`~wearpose.estimators.checkpoint.NetworkCheckpointing`
survive load -> ``checkpoint()`` / ``save`` unchanged: weights, meta (BiRAE's sigma scale and
calibration included), train command and provenance equal the file's; the config holds every
field of the file's with its value, plus the fields added to the config class since, at their
defaults (the training mix of issue 24: a file without them trained without them)."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from wearpose.estimators import get_estimator
from wearpose.estimators.checkpoint import load_checkpoint
from wearpose.weights import list_weights, weight_path

FIELDS = ("method", "kit", "sensors", "body_asset", "data_fingerprint", "train_command", "meta")


@pytest.mark.parametrize("name,method", [("imuposer_cpu", "imuposer"), ("birae6_cpu", "birae"), ("birae3_cpu", "birae")])
def test_shipped_weights_resave_identically(name: str, method: str, tmp_path: Path) -> None:
    if name not in list_weights():
        pytest.skip(f"{name} not shipped")
    raw = torch.load(weight_path(name), weights_only=True)
    est = get_estimator(method).load(weight_path(name))
    for ck in (est.checkpoint().to_dict(), load_checkpoint(est.save(tmp_path / "re.pt")).to_dict()):
        assert {k: ck[k] for k in FIELDS} == {k: raw[k] for k in FIELDS}
        assert {k: ck["config"][k] for k in raw["config"]} == raw["config"]
        added = {k: v for k, v in ck["config"].items() if k not in raw["config"]}
        defaults = type(est.config)().to_dict()
        assert added == {k: defaults[k] for k in added}, added
        assert set(ck["weights"]) == set(raw["weights"])
        assert all(torch.equal(ck["weights"][k], raw["weights"][k]) for k in raw["weights"])
    if method == "birae":  # the extra meta comes back as estimator state
        assert est.sigma_scale == float(raw["meta"].get("sigma_scale", 1.0))
        assert est.calibration == dict(raw["meta"].get("calibration") or {})

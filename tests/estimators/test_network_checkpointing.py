"""The to / checkpoint / save / load glue shared by single-network estimators
(:class:`~wearpose.estimators.checkpoint.NetworkCheckpointing`, used by PIP and MI-Poser)."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from wearpose.body import BodyModel
from wearpose.estimators.checkpoint import CheckpointMismatchError, NetworkCheckpointing, load_checkpoint
from wearpose.estimators.miposer import MiposerConfig, MiposerEstimator
from wearpose.estimators.pip import PipConfig, PipEstimator


@pytest.mark.parametrize("make", [lambda b: PipEstimator(PipConfig.preset("tiny"), body=b, physics=False),
                                  lambda b: MiposerEstimator(MiposerConfig.preset("tiny"), body=b)], ids=["pip", "miposer"])
def test_checkpoint_save_load_roundtrip(make, body: BodyModel, tmp_path: Path) -> None:
    torch.manual_seed(0)
    est = make(body)
    assert isinstance(est, NetworkCheckpointing) and est.to("cpu") is est and est.device == torch.device("cpu")
    est.data_fingerprint, est.train_command, est.meta = "fp", "wearpose train x", {"epoch": 3}
    ck = est.checkpoint({"val": 1.5}, {"global_step": 7})
    assert (ck.method, ck.kit, ck.sensors, ck.body_asset) == (est.name, est.kit_name, list(est.sensor_names), body.asset_id)
    assert ck.config == est.config.to_dict() and ck.meta == {"epoch": 3, "val": 1.5} and ck.train_state == {"global_step": 7}
    assert est.meta == {"epoch": 3}  # the extra meta goes to the checkpoint only
    assert set(ck.weights) == set(est.model.state_dict()) and all(w.device.type == "cpu" for w in ck.weights.values())
    path = est.save(tmp_path / "m.pt")
    assert load_checkpoint(path).train_state is None
    back = type(est).load(path, body=body)
    assert (back.data_fingerprint, back.train_command, back.meta) == ("fp", "wearpose train x", {"epoch": 3})
    assert all(torch.equal(v, back.model.state_dict()[k]) for k, v in est.model.state_dict().items())
    assert type(est).load(path).body_asset_id == body.asset_id  # body None: the embedded one, checked
    with pytest.raises(CheckpointMismatchError, match="kit"):
        type(est).load(path, kit="em12")
    with pytest.raises(CheckpointMismatchError, match="method"):
        (MiposerEstimator if isinstance(est, PipEstimator) else PipEstimator).load(path)

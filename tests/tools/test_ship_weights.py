"""tools/ship_weights.py: the card's training-data sentence comes from the method's config."""

from __future__ import annotations

import json
from dataclasses import replace
from typing import Any

import pytest

from tests.tools.tool_loader import load_tool
from wearpose.errors import ConfigError
from wearpose.estimators import get_estimator
from wearpose.weights import WEIGHTS_DIR

ship_weights = load_tool("ship_weights")


def _described_cards() -> list[dict[str, Any]]:
    """Shipped cards whose method is a registered estimator with a description."""
    out = []
    for p in sorted(WEIGHTS_DIR.glob("*.json")):
        card = json.loads(p.read_text())
        try:
            cls = get_estimator(card["method"])
        except ConfigError:  # e.g. the N-BEATS forecaster: not an estimator
            continue
        if cls.training_data_description(card["config"]) is not None:
            out.append(card)
    return out


CARDS = _described_cards()


def test_cards_found() -> None:
    assert {"pip_cpu", "empose12_cpu", "birae6_cpu", "miposer_cpu", "imuposer_cpu"} <= {c["name"] for c in CARDS}


@pytest.mark.parametrize("card", CARDS, ids=[c["name"] for c in CARDS])
def test_shipped_card_sentence(card: dict[str, Any]) -> None:
    text = get_estimator(card["method"]).training_data_description(card["config"])
    assert isinstance(text, str) and text.strip()
    assert card["kit"] in text
    if card["name"] == "pip_cpu":
        assert "mirror" in text and "0.8-1.25" in text and "150 synthetic sitting clips" in text
        assert "balanced" in text


def test_pip_without_augmentation() -> None:
    from wearpose.estimators.pip.config import PipConfig

    cfg = PipConfig.preset("cpu")
    text = get_estimator("pip").training_data_description(cfg.to_dict())
    assert "imu6" in text and "200 frames every 100" in text
    for word in ("mirror", "speed", "sitting", "padded"):
        assert word not in text


def test_pip_unbalanced_sitting_and_min_window() -> None:
    from wearpose.estimators.pip.config import PipConfig

    cfg = replace(PipConfig.preset("cpu"), sitting_clips=20, sitting_stand_s=(1.0, 4.0), aug_speed_copies=2,
                  min_window=60)
    text = get_estimator("pip").training_data_description(cfg.to_dict())
    assert "20 synthetic sitting clips" in text and "standing holds of 1-4 s" in text and "balanced" not in text
    assert "2 copies" in text and "mirror" not in text
    assert "60 to 199 frames as one padded window" in text and "sitting clips in windows" not in text
    mixed = get_estimator("pip").training_data_description(replace(cfg, sitting_window=50).to_dict())
    assert "sitting clips in windows of 50 frames every 25" in mixed


def test_empose_sentence() -> None:
    from wearpose.estimators.empose.config import EmposeConfig

    text = get_estimator("empose").training_data_description(EmposeConfig.preset("cpu", 6).to_dict())
    assert "EM" in text and "em6" in text and "random subject offsets" in text
    ablation = replace(EmposeConfig.preset("cpu", 12), offsets="none", train_noise="none")
    text = get_estimator("empose-resnet").training_data_description(ablation.to_dict())
    assert "no subject offsets" in text and "no noise" in text and "dropped" not in text


class FakeStore:
    """The three CorpusStore methods build_card reads."""

    ENTRIES = {"a": {"split": "train", "source": "bandai", "licence": "CC-BY-NC-4.0"},
               "b": {"split": "train", "source": "cmu_daz", "licence": "CMU-mocap-terms"},
               "c": {"split": "val", "source": "bandai", "licence": "CC-BY-NC-4.0"}}

    def clips(self, split: str | None = None) -> list[str]:
        return sorted(k for k, e in self.ENTRIES.items() if split is None or e["split"] == split)

    def entry(self, clip: str) -> dict[str, Any]:
        return self.ENTRIES[clip]

    def provenance(self) -> dict[str, Any]:
        return {"path": "/s", "converter": "motion-4",
                "corpus": {"kind": "manifest", "name": "data-v2", "path": "/d", "manifest_sha1": "9" * 40}}


def _checkpoint(method: str, config: dict[str, Any]) -> dict[str, Any]:
    return {"method": method, "kit": "imu6", "sensors": ["pelvis"], "body_asset": "x", "config": config,
            "train_command": "wearpose train ...", "data_fingerprint": "f" * 8, "meta": {"epoch": 3, "val_loss": 0.5}}


def test_build_card() -> None:
    from wearpose.estimators.pip.config import PipConfig

    config = replace(PipConfig.preset("cpu"), aug_mirror=True).to_dict()
    kw = {"size_bytes": 10, "storage": "float32", "shipped_with": "python tools/ship_weights.py x y", "store": FakeStore()}
    card = ship_weights.build_card(_checkpoint("pip", config), "pip_test", **kw)
    td = card["training_data"]
    assert td["simulation"] == get_estimator("pip").training_data_description(config)
    assert "mirror" in td["simulation"]
    assert td["clips"] == 2 and td["clips_per_source"] == {"bandai": 1, "cmu_daz": 1}
    assert td["corpus"]["name"] == "data-v2" and td["corpus"]["manifest_sha1"] == "9" * 40
    assert card["licence"].startswith("non-commercial") and card["validation"] == {"epoch": 3, "val_loss": 0.5}
    assert card["name"] == "pip_test" and "notes" not in card and "recipe" not in card
    ck = _checkpoint("pip", config)
    ck["meta"]["recipe"] = {"name": "pip_test", "method": "pip", "options": {"config": "cpu"}, "seed": 0}
    assert ship_weights.build_card(ck, "pip_test", **kw)["recipe"] == ck["meta"]["recipe"]  # issue 24: recipe on the card
    card = ship_weights.build_card(_checkpoint("pip", config), "pip_test", simulation="by hand", notes="n", **kw)
    assert card["training_data"]["simulation"] == "by hand" and card["notes"] == "n"


@pytest.mark.parametrize("method", ["empose-lbfgs", "nbeats-forecaster"])
def test_build_card_without_description(method: str) -> None:
    from wearpose.estimators.empose.config import EmposeConfig

    ck = _checkpoint(method, EmposeConfig.preset("cpu", 12).to_dict())
    kw = {"size_bytes": 10, "storage": "float32", "shipped_with": "s", "store": FakeStore()}
    with pytest.raises(ConfigError, match=rf"{method}.*--simulation"):
        ship_weights.build_card(ck, "x", **kw)
    assert ship_weights.build_card(ck, "x", simulation="poses only", **kw)["training_data"]["simulation"] == "poses only"

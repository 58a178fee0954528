"""The training mix every method shares (wearpose.estimators.trainmix): which clips the train
split gets beyond its corpus clips, how each loads, the wearers and the site jitter, and that
validation never changes. Tiny synthetic clips, one thread."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from tests.estimators.pip.test_pip_kinematics import FakeStore as Store
from wearpose.errors import ConfigError
from wearpose.estimators.checkpoint import CheckpointMismatchError
from wearpose.estimators.empose import EmposeConfig
from wearpose.estimators.empose.baselines import estimator_class
from wearpose.estimators.empose.data import build_split
from wearpose.estimators.method import TrainRun
from wearpose.estimators.trainmix import TrainingMix, TrainingStore, clip_body, mix_clause, training_source
from wearpose.geometry import geodesic_angle
from wearpose.motion.augment import LOWER_BODY
from wearpose.motion.procedural import FAMILIES


def tiny(**kw) -> EmposeConfig:
    return EmposeConfig.preset("tiny").override(**kw)


def test_without_a_mix_the_split_is_unchanged(tmp_path: Path, body) -> None:
    store = Store(tmp_path, {"train": 3})
    ids = store.clips("train")
    s, got, extra = training_source("train", store, ids, tiny(), body, "empose")
    assert s is store and got == ids and extra == {}
    assert not TrainingMix.from_config(tiny()).active and TrainingMix().settings() == {}


def test_the_mix_adds_copies_then_procedural_clips_and_only_to_train(tmp_path: Path, body) -> None:
    store = Store(tmp_path, {"train": 2, "val": 2})
    cfg = tiny(aug_mirror=True, aug_heading_copies=1, procedural_per_family=2, train_shapes="random")
    ids = store.clips("train")
    s, got, extra = training_source("train", store, ids, cfg, body, "empose")
    assert isinstance(s, TrainingStore)
    assert got[:6] == [*ids, f"{ids[0]}#mirror", f"{ids[0]}#heading0", f"{ids[1]}#mirror", f"{ids[1]}#heading0"]
    assert got[6:] == [f"procedural/{f}/train/{i:04d}" for f in FAMILIES for i in range(2)]
    assert extra["mix"]["shapes"] == "random" and extra["mix"]["procedural_per_family"] == 2
    assert extra["mix"]["augment"]["mirror"] is True
    v, vids, vextra = training_source("val", store, store.clips("val"), cfg, body, "empose")
    assert v is store and vids == store.clips("val") and vextra == {}


def test_random_wearers_are_per_clip_and_the_same_for_every_method(tmp_path: Path, body) -> None:
    store = Store(tmp_path, {"train": 2})
    ids = store.clips("train")
    mix = TrainingMix(shapes="random")
    a = TrainingStore(store, mix, body, ids, 0, "empose")
    b = TrainingStore(store, mix, body, ids, 0, "pip-speed")
    m0, m0b, m1 = a.load(ids[0]), b.load(ids[0]), a.load(ids[1])
    assert torch.equal(m0.betas, m0b.betas)  # seeded by the clip, not the method
    assert not torch.equal(m0.betas, m1.betas) and float(m0.betas.abs().max()) > 0
    assert torch.equal(m0.pose, store.load(ids[0]).pose)  # joint rotations kept; root re-fitted
    assert not torch.equal(TrainingStore(store, mix, body, ids, 1, "empose").load(ids[0]).betas, m0.betas)


def test_heading_and_mix_copies_load_from_the_corpus_clip(tmp_path: Path, body) -> None:
    store = Store(tmp_path, {"train": 3})
    ids = store.clips("train")
    mix = TrainingMix.from_config(tiny(aug_heading_copies=1, aug_mix_copies=1))
    ts = TrainingStore(store, mix, body, ids, 0, "empose")
    src = store.load(ids[0])
    turned = ts.load(f"{ids[0]}#heading0")
    assert torch.allclose(turned.pose[:, 1:], src.pose[:, 1:])
    ang = geodesic_angle(turned.pose[:, 0], src.pose[:, 0])
    assert float(ang.max() - ang.min()) < 1e-4  # one constant turn of the whole clip
    mixed = ts.load(f"{ids[0]}#mix0")
    lower = list(LOWER_BODY)
    assert torch.equal(mixed.pose[:, lower], src.pose[:mixed.num_frames, lower])
    assert torch.equal(mixed.trans, src.trans[:mixed.num_frames])
    upper = [j for j in range(24) if j not in lower]
    partners = [store.load(c) for c in ids]
    assert any(torch.equal(mixed.pose[:, upper], p.pose[:mixed.num_frames, upper]) for p in partners)
    assert ts.load(f"{ids[0]}#mix0").meta == mixed.meta  # the same partner every time


def test_procedural_clips_load_by_id_on_the_mean_or_a_drawn_body(tmp_path: Path, body) -> None:
    store = Store(tmp_path, {"train": 1})
    mean = TrainingStore(store, TrainingMix(procedural_per_family=1), body, [], 0, "empose")
    drawn = TrainingStore(store, TrainingMix(procedural_per_family=1, shapes="random"), body, [], 0, "empose")
    a, b = mean.load("procedural/pickup/train/0000"), drawn.load("procedural/pickup/train/0000")
    assert a.meta["clip"] == "procedural/pickup/train/0000" and a.fps == 60.0
    assert float(a.betas.abs().max()) == 0.0 and float(b.betas.abs().max()) > 0.0


def test_site_jitter_moves_sites_per_clip(tmp_path: Path, body) -> None:
    store = Store(tmp_path, {"train": 2})
    plain = TrainingStore(store, TrainingMix(), body, [], 0, "empose")
    assert clip_body(plain, "x", body) is body and clip_body(store, "x", body) is body
    mix = TrainingMix.from_config(tiny(aug_site_jitter_m=0.05))
    ts = TrainingStore(store, mix, body, [], 0, "empose")
    j0, j0b, j1 = clip_body(ts, "a", body), clip_body(ts, "a", body), clip_body(ts, "b", body)
    assert list(j0._site_vertices) == list(j0b._site_vertices)
    assert list(j0._site_vertices) != list(body._site_vertices)
    assert list(j0._site_vertices) != list(j1._site_vertices)
    v = body.v_template
    moved = (v[torch.as_tensor(j0._site_vertices)] - v[torch.as_tensor(body._site_vertices)]).norm(dim=-1)
    assert float(moved.max()) <= 0.05 + 1e-6


def test_rest_offsets_turn_each_train_clip_by_its_own_draw(tmp_path: Path, body) -> None:
    """aug_rest_offset_deg: in place (no extra ids), per clip, reproducible, up to the angle, and
    only in the training split's store; the fingerprint changes, runs without it keep theirs."""
    store = Store(tmp_path, {"train": 2, "val": 1})
    ids = store.clips("train")
    cfg = tiny(aug_rest_offset_deg=25.0)
    ts, got, extra = training_source("train", store, ids, cfg, body, "empose")
    assert got == ids and extra["mix"]["augment"]["rest_offset_deg"] == 25.0
    assert "rest_offset_deg" not in TrainingMix.from_config(tiny(aug_mirror=True)).settings()["augment"]
    a, a2, b = ts.load(ids[0]), ts.load(ids[0]), ts.load(ids[1])
    plain_a, plain_b = store.load(ids[0]), store.load(ids[1])
    assert torch.equal(a.pose, a2.pose) and a.meta["augment"] == ["rest_offset"]
    da = torch.rad2deg(geodesic_angle(a.pose[:, 1:], plain_a.pose[:, 1:].to(a.pose)))
    db = torch.rad2deg(geodesic_angle(b.pose[:, 1:], plain_b.pose[:, 1:].to(b.pose)))
    assert float(da.max()) <= 2 * 25.0 + 1e-4 and float(da.mean()) > 1.0  # a local turn is C_p^T R C_j: two offsets
    assert not torch.allclose(da, db)  # each clip its own offsets
    assert training_source("val", store, store.clips("val"), cfg, body, "empose")[0] is store
    assert "25 deg" in TrainingMix.from_config(cfg).describe()
    assert TrainingMix.from_config(cfg).corpus_settings()["rest_offset_deg"] == 25.0
    # on named joints only: the others keep the corpus rotation
    ts2, _, _ = training_source("train", store, ids, tiny(aug_rest_offset_deg=25.0, aug_rest_offset_joints=("neck",)),
                                body, "empose")
    c = ts2.load(ids[0])
    d = torch.rad2deg(geodesic_angle(c.pose, plain_a.pose.to(c.pose)))
    from wearpose.body.skeleton import JOINT_INDEX, PARENTS

    moved = {JOINT_INDEX["neck"], *[j for j, p in enumerate(PARENTS) if p == JOINT_INDEX["neck"]]}
    assert float(d[:, sorted(moved)].max()) > 0.5 and float(d[:, [j for j in range(24) if j not in moved]].max()) < 1e-3
    assert "the neck joints" in TrainingMix.from_config(tiny(aug_rest_offset_deg=25.0,
                                                             aug_rest_offset_joints=("neck",))).describe()


def test_empose_train_split_holds_the_wearers_shapes(tmp_path: Path, body) -> None:
    """EM-POSE's shape target follows the wearer, so its shape estimate trains (issue 24.5)."""
    store = Store(tmp_path / "store", {"train": 2, "val": 1})
    cfg = tiny(aug_mirror=True, train_shapes="random")
    tr = build_split("train", cfg, body, store=store, cache_root=tmp_path / "cache")
    assert len(tr.clip_ids) == 4 and tr.clip_ids[2:] == [f"{c}#mirror" for c in store.clips("train")]
    assert tr.betas.shape == (4, 10) and len({tuple(b.tolist()) for b in tr.betas}) == 4
    plain = build_split("train", tiny(), body, store=store, cache_root=tmp_path / "cache")
    assert plain.fingerprint != tr.fingerprint and float(plain.betas.abs().max()) == 0.0
    assert build_split("val", cfg, body, store=store, cache_root=tmp_path / "cache").clip_ids == store.clips("val")


@pytest.mark.parametrize("bad", [{"aug_speed_copies": -1}, {"procedural_per_family": -2}, {"aug_site_jitter_m": 0.5},
                                 {"aug_rest_offset_deg": 60.0}, {"train_shapes": "giant"}, {"aug_speed_range": (1.2, 0.9)}])
def test_config_refuses_bad_mix_fields(bad) -> None:
    with pytest.raises(ConfigError, match=next(iter(bad))):
        tiny(**bad)


def test_train_run_sets_seed_and_mix_on_the_config() -> None:
    run = TrainRun(seed=7, mirror=True, procedural=3, shapes="random", site_jitter=0.02, rest_offset=20.0,
                   rest_offset_joints="neck, left_collar")
    cfg = tiny().override(**run.config_overrides())
    assert (cfg.seed, cfg.aug_mirror, cfg.procedural_per_family, cfg.train_shapes, cfg.aug_site_jitter_m,
            cfg.aug_rest_offset_deg, cfg.aug_rest_offset_joints) == (7, True, 3, "random", 0.02, 20.0,
                                                                     ("neck", "left_collar"))
    assert tiny().override(**TrainRun().config_overrides()) == tiny()  # nothing given: the preset's


def test_families_leave_some_out_and_unknown_ones_are_refused(tmp_path: Path, body) -> None:
    """--families crawl,lie... draws only those families: the others stay motion the model never saw."""
    run = TrainRun(procedural=2, families="squat, kneel,reach")
    cfg = tiny().override(**run.config_overrides())
    assert cfg.procedural_families == ("squat", "kneel", "reach")
    assert EmposeConfig.from_dict(cfg.to_dict()) == cfg  # the checkpoint's config keeps the tuple
    store = Store(tmp_path, {"train": 1})
    _, got, extra = training_source("train", store, store.clips("train"), cfg, body, "empose")
    assert got[1:] == [f"procedural/{f}/train/{i:04d}" for f in ("squat", "kneel", "reach") for i in range(2)]
    assert extra["mix"]["families"] == ["squat", "kneel", "reach"]
    assert "(squat, kneel, reach;" in mix_clause(cfg) and "crawl" not in mix_clause(cfg)
    assert TrainingMix.from_config(tiny(procedural_per_family=2)).families == FAMILIES  # default: all seven
    with pytest.raises(ConfigError, match=r"procedural_families: unknown families \['cartwheel'\]; expected some of squat"):
        TrainingMix.from_config(tiny(procedural_families=("squat", "cartwheel")))
    with pytest.raises(ConfigError, match="procedural_families: expected distinct family names"):
        tiny(procedural_families=("lie", "lie"))


def test_warm_start_loads_matching_weights_and_names_a_mismatch(tmp_path: Path, body) -> None:
    cls = estimator_class("lgd")
    src = cls(tiny(), body=body)
    path = src.save(tmp_path / "a.pt")
    dst = cls(tiny(seed=3), body=body)
    assert not all(torch.equal(a, b) for a, b in zip(src.model.state_dict().values(), dst.model.state_dict().values()))
    dst.warm_start(path)
    assert all(torch.equal(a, b) for a, b in zip(src.model.state_dict().values(), dst.model.state_dict().values()))
    assert dst.meta["init_from"] == str(path)
    wide = cls(tiny(hidden=tiny().hidden * 2), body=body)
    with pytest.raises(CheckpointMismatchError, match="this network's is"):
        wide.warm_start(path)


def test_the_card_sentence_names_every_part_of_the_mix() -> None:
    assert TrainingMix().describe() == ""
    text = TrainingMix.from_config(tiny(aug_mirror=True, aug_speed_copies=2, aug_heading_copies=1, aug_mix_copies=1,
                                        aug_site_jitter_m=0.02, procedural_per_family=5, train_shapes="random")).describe()
    for words in ("mirror image", "2 copies played at a speed drawn log-uniformly from 0.8-1.25x", "one copy turned",
                  "upper body of another", "5 procedural clips of each family", "adult body drawn", "up to 2 cm"):
        assert words in text, (words, text)


def test_every_methods_card_sentence_names_its_mix() -> None:
    """EM-POSE, PIP, BiRAE and MI-Poser describe the same mix in the same words (EM-POSE's card
    sentence used to leave it out); without a mix the sentence has no mix clause."""
    from wearpose.estimators.registry import get_estimator

    mix = {"aug_mirror": True, "procedural_per_family": 20}
    clause = mix_clause(tiny(**mix))
    assert clause.startswith("; plus ") and "20 procedural clips" in clause and mix_clause(tiny()) == ""
    for name in ("empose", "pip", "birae", "miposer"):
        cls = get_estimator(name)
        assert "; plus" not in cls.training_data_description({}), name
        assert clause in cls.training_data_description(mix), name

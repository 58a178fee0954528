"""PIP's augmentation goes through the shared training mix (wearpose.estimators.trainmix, on
wearpose.motion.augment): the augmented clips are bit-identical to what PIP's own code made
before (the old code is kept here as the reference)."""

from __future__ import annotations

import math

import torch

from tests.estimators.pip.test_pip_kinematics import FakeStore, tiny
from wearpose.body import BodyModel
from wearpose.estimators.seeding import clip_seed
from wearpose.estimators.pip.data import AUG_NAMESPACE
from wearpose.estimators.trainmix import TrainingMix, TrainingStore
from wearpose.motion import mirror, play_speed


def _former_ids(ids: list[str], cfg) -> list[str]:
    tags = (["mirror"] if cfg.aug_mirror else []) + [f"speed{k}" for k in range(cfg.aug_speed_copies)]
    return [f"{cid}#{t}" for cid in ids for t in tags]


def _former_motion(aid: str, store, cfg, body):
    cid, tag = aid.rsplit("#", 1)
    m = store.load(cid)
    root_rest = body.rest_joints(m.betas.to(body.dtype))[0]
    if tag == "mirror":
        return mirror(m, root_rest)
    g = torch.Generator().manual_seed(clip_seed(aid, cfg.seed, "pip-speed"))
    u, flip = torch.rand(2, generator=g, dtype=torch.float64).tolist()
    lo, hi = (math.log(v) for v in cfg.aug_speed_range)
    m = play_speed(m, math.exp(lo + u * (hi - lo)))
    return mirror(m, root_rest) if cfg.aug_mirror and flip < 0.5 else m


def test_pip_augmented_clips_bit_identical_to_the_former_code(tmp_path) -> None:
    body = BodyModel()
    store = FakeStore(tmp_path, {"train": 4})
    for cfg in (tiny(aug_mirror=True, aug_speed_copies=3, aug_speed_range=(0.7, 1.4)),
                tiny(aug_mirror=False, aug_speed_copies=2), tiny(aug_mirror=True, aug_speed_copies=0, seed=5)):
        ids = store.clips("train")
        mix = TrainingMix.from_config(cfg)
        tstore = TrainingStore(store, mix, body, ids, cfg.seed, AUG_NAMESPACE)
        assert mix.extra_ids(ids) == _former_ids(ids, cfg)
        for aid in mix.extra_ids(ids):
            new, old = tstore.load(aid), _former_motion(aid, store, cfg, body)
            assert torch.equal(new.pose, old.pose) and torch.equal(new.trans, old.trans), aid
            assert torch.equal(new.betas, old.betas) and new.fps == old.fps and new.meta == old.meta, aid
        # the settings a recipe records
        d = mix.augment.to_dict()
        assert d["mirror"] == cfg.aug_mirror and d["speed_copies"] == cfg.aug_speed_copies
        assert d["speed_range"] == list(cfg.aug_speed_range) and d["heading_copies"] == 0

"""The training mix: what a method's *train* split holds beyond its corpus clips, one place for
every method (issue 24, items 2, 3 and 5).

A method's config (:class:`~wearpose.estimators.trainconfig.TrainConfig`) says which extras its
training data gets; :class:`TrainingMix` is that choice in one recordable form, and
:func:`training_source` turns a split's corpus clip ids and store into the ids and store the
method's data builder iterates over:

- **augmented copies** of the corpus clips (:mod:`wearpose.motion.augment`): ``<id>#mirror``,
  ``<id>#speed<k>``, ``<id>#heading<k>``, ``<id>#mix<k>`` (the sensors are simulated from the
  augmented motion, so every target follows it);
- **procedural clips** of the families the corpus lacks (:mod:`wearpose.motion.procedural`:
  squat, kneel, pick up, sit, lie down, crawl, reach), ``procedural/<family>/train/<i>``, drawn
  from the ``train`` seed namespace (the unseen-motion protocol draws from ``eval``);
- **wearers**: with ``train_shapes="random"`` every clip (corpus, augmented, procedural) is worn
  by one adult body drawn for it (:func:`wearpose.sensors.random_body_shape`, the training
  stream) and re-fitted to it (:func:`wearpose.motion.refit_to_body`); a clip has the same wearer
  for every method (seeded by the clip id in the ``train-body`` namespace, not per method);
- **sensor placement**: :meth:`TrainingStore.body_for` gives the body whose sensor sites moved by
  up to ``aug_site_jitter_m`` (:func:`wearpose.motion.augment.jitter_sites`), drawn per clip;
- **capture chain**: with ``aug_rest_offset_deg`` every clip's joints are turned by constant
  offsets drawn for it (:func:`wearpose.motion.augment.offset_rest`, namespace ``rest-offset``),
  before its wearer is fitted.

Validation and test splits never change: :func:`training_source` returns them as they are.
:meth:`TrainingMix.settings` goes into the data fingerprint (empty when nothing is added, so the
caches of runs without a mix stay valid).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import torch

from wearpose.body.skeleton import JOINT_INDEX
from wearpose.errors import ConfigError
from wearpose.estimators.seeding import clip_seed
from wearpose.motion.augment import (AugmentSettings, augment_clip, augmented_ids, jitter_sites, offset_rest,
                                     random_rest_offsets)
from wearpose.motion.procedural import FAMILIES, PREFIX, procedural_clip
from wearpose.motion.procedural import clip_id as procedural_id
from wearpose.motion.sequence import MotionSequence

#: Seed namespace of the training wearers (``train_shapes="random"``).
BODY_NAMESPACE = "train-body"
#: Seed namespace of the per-clip sensor-site draws (``aug_site_jitter_m``).
JITTER_NAMESPACE = "site-jitter"
#: Seed namespace of the per-clip joint offsets (``aug_rest_offset_deg``).
REST_OFFSET_NAMESPACE = "rest-offset"
#: Frame rate the procedural clips are made at (methods resample to their own).
PROCEDURAL_FPS = 60.0


@dataclass(frozen=True)
class TrainingMix:
    """Which extras the train split gets (module doc).

    Attributes:
        augment: the augmented copies and site jitter (:class:`~wearpose.motion.augment.AugmentSettings`).
        procedural_per_family: procedural clips of each family in ``families``.
        shapes: ``"corpus"`` (the clips' own bodies) or ``"random"`` (a wearer per clip).
        families: the procedural families drawn from.
    """

    augment: AugmentSettings = AugmentSettings()
    procedural_per_family: int = 0
    shapes: str = "corpus"
    families: tuple[str, ...] = FAMILIES

    @classmethod
    def from_config(cls, cfg: Any) -> TrainingMix:
        """The mix a :class:`~wearpose.estimators.trainconfig.TrainConfig` asks for."""
        aug = AugmentSettings(mirror=bool(cfg.aug_mirror), speed_copies=int(cfg.aug_speed_copies),
                              speed_range=tuple(cfg.aug_speed_range), heading_copies=int(cfg.aug_heading_copies),
                              mix_copies=int(cfg.aug_mix_copies), site_jitter_m=float(cfg.aug_site_jitter_m),
                              rest_offset_deg=float(cfg.aug_rest_offset_deg),
                              rest_offset_joints=tuple(cfg.aug_rest_offset_joints))
        families = tuple(cfg.procedural_families) or FAMILIES
        unknown = [f for f in families if f not in FAMILIES]
        if unknown:
            raise ConfigError(f"{type(cfg).__name__}.procedural_families: unknown families {unknown}; expected some of "
                              f"{', '.join(FAMILIES)}")
        return cls(aug, int(cfg.procedural_per_family), str(cfg.train_shapes), families)

    @property
    def adds_clips(self) -> bool:
        """Whether the train split gets clips beyond its corpus clips."""
        return bool(self.augment.tags()) or self.procedural_per_family > 0

    @property
    def active(self) -> bool:
        """Whether the train split differs from its corpus clips at all."""
        return (self.adds_clips or self.shapes != "corpus" or self.augment.site_jitter_m > 0
                or self.augment.rest_offset_deg > 0)

    def settings(self) -> dict[str, Any]:
        """What the data fingerprint holds of the mix: ``{}`` when inactive, else every field."""
        if not self.active:
            return {}
        return {"mix_version": 1, "augment": self.augment.to_dict(), "procedural_per_family": self.procedural_per_family,
                "shapes": self.shapes, "families": list(self.families)}

    def corpus_settings(self) -> dict[str, Any]:
        """What changes the *corpus* clips themselves (their wearers and sensor sites), for a
        cache that keeps them apart from the added clips (PIP's): ``{}`` when none does."""
        a = self.augment
        if self.shapes == "corpus" and a.site_jitter_m <= 0 and a.rest_offset_deg <= 0:
            return {}
        out: dict[str, Any] = {"wearers": self.shapes, "site_jitter_m": a.site_jitter_m}
        if a.rest_offset_deg > 0:
            out["rest_offset_deg"] = a.rest_offset_deg
            if a.rest_offset_joints:
                out["rest_offset_joints"] = list(a.rest_offset_joints)
        return out

    def describe(self) -> str:
        """The weight card's sentence about the mix (``""`` when inactive): what the train split
        held beyond its corpus clips, and their licences."""
        a, parts = self.augment, []
        if a.mirror:
            parts.append("the left/right mirror image of every clip")
        if a.speed_copies:
            parts.append(f"{_copies(a.speed_copies)} played at a speed drawn log-uniformly from "
                         f"{a.speed_range[0]:g}-{a.speed_range[1]:g}x" + (" (mirrored with probability 1/2)" if a.mirror else ""))
        if a.heading_copies:
            parts.append(f"{_copies(a.heading_copies)} turned to a uniform random heading")
        if a.mix_copies:
            parts.append(f"{_copies(a.mix_copies)} with the upper body of another train clip")
        text = ("augmented copies of the same train clips (same sources and licences): " + " and ".join(parts)
                + ", wearpose.motion.augment, simulated after augmenting") if parts else ""
        extra = []
        if self.procedural_per_family:
            extra.append(f"{self.procedural_per_family} procedural clips of each family ({', '.join(self.families)}; "
                         "wearpose.motion.procedural, train seed namespace; generated here, no licence restriction)")
        if self.shapes == "random":
            extra.append("every clip worn by an adult body drawn for it (wearpose.body.shapes, train stream) and "
                         "re-fitted to it")
        if a.site_jitter_m > 0:
            extra.append(f"sensor sites jittered up to {a.site_jitter_m * 100:g} cm per clip")
        if a.rest_offset_deg > 0:
            which = f"the {', '.join(a.rest_offset_joints)} joints" if a.rest_offset_joints else "every clip's joints"
            extra.append(f"{which} turned by constant offsets of up to {a.rest_offset_deg:g} deg drawn per clip "
                         "(another capture chain's rest pose; wearpose.motion.augment.offset_rest)")
        return "; ".join(x for x in (text, *extra) if x)

    def extra_ids(self, corpus_ids: Sequence[str]) -> list[str]:
        """Ids of the clips added to corpus clips ``corpus_ids``: their augmented copies, then the
        procedural clips family by family."""
        procedural = [procedural_id(f, "train", i) for f in self.families for i in range(self.procedural_per_family)]
        return [*augmented_ids(list(corpus_ids), self.augment), *procedural]


def mix_clause(cfg: Any) -> str:
    """What every method's card sentence (``training_data_description``) ends with about the
    training mix of ``cfg`` (a :class:`~wearpose.estimators.trainconfig.TrainConfig`):
    ``"; plus "`` and :meth:`TrainingMix.describe`, or ``""`` when the mix is inactive."""
    text = TrainingMix.from_config(cfg).describe()
    return f"; plus {text}" if text else ""


def _copies(n: int) -> str:
    return "one copy" if n == 1 else f"{n} copies"


class TrainingStore:
    """A corpus store that also loads the training mix's clips (module doc); everything but
    :meth:`load`, :meth:`body_for` and :meth:`betas` is the wrapped store's.

    Args:
        store: the split's :class:`~wearpose.motion.CorpusStore` (or a subset of it).
        mix: the mix; body: the :class:`~wearpose.body.BodyModel` wearers are fitted on and
            procedural clips placed on; corpus_ids: the split's corpus clips (the partners of
            ``mix`` copies); seed: the config's base seed; namespace: the method's seed namespace
            of the augmentation draws (PIP: ``pip-speed``, the draws its shipped data used).
    """

    def __init__(self, store: Any, mix: TrainingMix, body: Any, corpus_ids: Sequence[str], seed: int,
                 namespace: str) -> None:
        self.store, self.mix, self.body = store, mix, body
        self.corpus_ids, self.seed, self.namespace = list(corpus_ids), int(seed), namespace

    def __getattr__(self, name: str) -> Any:
        if name in ("store", "mix", "body", "corpus_ids", "seed", "namespace"):  # not set yet: no recursion
            raise AttributeError(name)
        return getattr(self.store, name)

    def betas(self, clip_id: str, num_betas: int = 10) -> torch.Tensor:
        """The training wearer of clip ``clip_id`` ``(num_betas,)`` (``shapes="random"``)."""
        from wearpose.sensors import random_body_shape  # start-up: sensors adds ~304 ms to import this module

        return random_body_shape(clip_seed(clip_id, self.seed, BODY_NAMESPACE), num_betas, "random")

    def load(self, clip_id: str) -> MotionSequence:
        """Corpus clip, augmented copy or procedural clip ``clip_id``, on its wearer (with its joint
        offsets first when ``aug_rest_offset_deg``; a procedural clip is made on its wearer)."""
        if clip_id.startswith(PREFIX):
            family, _, index = clip_id[len(PREFIX):].split("/")
            return self._offset(clip_id, procedural_clip(family, int(index), self._body(), seed=self.seed,
                                                         namespace="train", fps=PROCEDURAL_FPS,
                                                         body_shape=self.mix.shapes == "random"))
        motion = self._augmented(clip_id) if "#" in clip_id else self.store.load(clip_id)
        motion = self._offset(clip_id, motion)
        if self.mix.shapes == "corpus":
            return motion
        from wearpose.motion import refit_to_body  # start-up: motion adds ~91 ms to import this module

        return refit_to_body(motion, self._body(), self.betas(clip_id, int(motion.betas.shape[-1])))

    def body_for(self, clip_id: str, body: Any) -> Any:
        """``body`` with its sensor sites jittered for clip ``clip_id`` (``aug_site_jitter_m``), or
        ``body`` itself without jitter."""
        radius = self.mix.augment.site_jitter_m
        if radius <= 0:
            return body
        g = torch.Generator().manual_seed(clip_seed(clip_id, self.seed, JITTER_NAMESPACE))
        return jitter_sites(body, radius, g)

    def _offset(self, clip_id: str, motion: MotionSequence) -> MotionSequence:
        max_deg = self.mix.augment.rest_offset_deg
        if max_deg <= 0:
            return motion
        g = torch.Generator().manual_seed(clip_seed(clip_id, self.seed, REST_OFFSET_NAMESPACE))
        joints = tuple(JOINT_INDEX[n] for n in self.mix.augment.rest_offset_joints)
        return offset_rest(motion, random_rest_offsets(max_deg, g, motion.pose.shape[1], joints))

    def _augmented(self, aid: str) -> MotionSequence:
        cid = aid.rsplit("#", 1)[0]
        motion = self.store.load(cid)
        body = self._body()
        root_rest = body.rest_joints(motion.betas.to(body.dtype))[0]
        g = torch.Generator().manual_seed(clip_seed(aid, self.seed, self.namespace))
        partner = None
        if aid.rsplit("#", 1)[1].startswith("mix"):
            pick = int(torch.randint(len(self.corpus_ids), (), generator=g))
            partner = self.store.load(self.corpus_ids[pick])
            if abs(partner.fps - motion.fps) > 1e-9:
                from wearpose.motion import resample  # start-up: motion adds ~91 ms to import this module

                partner = resample(partner, motion.fps)
        return augment_clip(aid, motion, self.mix.augment, g, root_rest, partner)

    def _body(self) -> Any:
        if self.body is None:  # methods without a body model (BiRAE): the embedded asset
            from wearpose.body import BodyModel  # start-up: body adds ~57 ms to import this module

            self.body = BodyModel()
        return self.body


def training_source(split: str, store: Any, ids: Sequence[str], cfg: Any, body: Any,
                    namespace: str) -> tuple[Any, list[str], dict[str, Any]]:
    """The store, clip ids and fingerprint settings a method's ``split`` is built from.

    For ``split == "train"`` with an active mix (:meth:`TrainingMix.from_config` of ``cfg``): a
    :class:`TrainingStore` over ``store``, ``ids`` followed by :meth:`TrainingMix.extra_ids`, and
    ``{"mix": ...}``; otherwise ``store``, ``ids`` and ``{}`` unchanged.
    """
    mix = TrainingMix.from_config(cfg)
    if split != "train" or not mix.active:
        return store, list(ids), {}
    tstore = TrainingStore(store, mix, body, ids, int(cfg.seed), namespace)
    return tstore, [*ids, *mix.extra_ids(ids)], {"mix": mix.settings()}


def clip_body(store: Any, clip_id: str, body: Any) -> Any:
    """The body clip ``clip_id``'s sensors are simulated on: ``store``'s
    :meth:`TrainingStore.body_for` for a training store, else ``body``."""
    return store.body_for(clip_id, body) if isinstance(store, TrainingStore) else body


__all__ = ["BODY_NAMESPACE", "JITTER_NAMESPACE", "PROCEDURAL_FPS", "REST_OFFSET_NAMESPACE", "TrainingMix",
           "TrainingStore", "clip_body", "mix_clause", "training_source"]

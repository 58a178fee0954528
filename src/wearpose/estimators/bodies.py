"""The wearers of evaluation clips: which body each clip is simulated on (issue 23.6, 24.6).

One place decides it for every method's protocol (``wearpose evaluate --bodies``,
:func:`wearpose.evaluate.protocols.evaluate_model`, EM-POSE's
:func:`~wearpose.estimators.empose.evaluate.evaluate_models`, PIP's
:func:`~wearpose.estimators.pip.evaluate.evaluate_variants`):

- ``"corpus"`` (default): the clip's own body, beta = 0 (the corpus is retargeted onto it);
  the store is used as it is, so every figure is the one measured before this option.
- ``"heldout"``: one wearer per clip, :func:`heldout_betas`: the held-out shape stream of
  :func:`wearpose.sensors.random_body_shape` (``draw="heldout"``, a stream no training path
  draws from) seeded by the clip id and the evaluation seed in the ``"eval-body"`` namespace
  (:func:`~wearpose.estimators.seeding.clip_seed`). The seed depends on the clip and the base
  seed only, not on the method, so a clip has the same wearer for every model and every
  method compared. The clip is re-fitted to that body as the simulator re-fits it
  (:func:`wearpose.motion.refit_to_body`: joint rotations kept, root height and travel from the
  new body's legs) when it is loaded (:class:`WearerStore`), so each protocol simulates its
  sensors on that body and scores against that body's ground truth without knowing about it.
"""

from __future__ import annotations

from typing import Any

import torch

from wearpose.errors import ConfigError
from wearpose.estimators.seeding import clip_seed

#: ``bodies`` values: the clip's own body, or a held-out wearer per clip.
BODIES = ("corpus", "heldout")
#: Seed namespace of the evaluation wearers (:func:`heldout_betas`).
BODY_NAMESPACE = "eval-body"


def check_bodies(bodies: str) -> str:
    """``bodies`` if it is one of :data:`BODIES`; else a :class:`ConfigError` naming them."""
    if bodies not in BODIES:
        raise ConfigError(f"bodies must be one of {', '.join(BODIES)}, got {bodies!r}")
    return bodies


def heldout_betas(clip_id: str, seed: int, num_betas: int = 10) -> torch.Tensor:
    """The held-out wearer of clip ``clip_id`` for evaluation seed ``seed``: betas
    ``(num_betas,)`` from the asset's adult shape distribution
    (:func:`wearpose.body.shapes.sample_betas`), module doc."""
    from wearpose.sensors import random_body_shape  # start-up: sensors adds ~304 ms to import this module

    return random_body_shape(clip_seed(clip_id, seed, BODY_NAMESPACE), num_betas, "heldout")


class WearerStore:
    """A corpus store whose clips load re-fitted to their held-out wearer (module doc).

    Everything but :meth:`load` is the wrapped store's (``clips``, ``entry``, ``provenance``,
    ``root``, ...). The last clip loaded is kept: protocols that read a clip twice in a row
    re-fit it once.
    """

    def __init__(self, store: Any, body: Any, seed: int) -> None:
        self.store, self.body, self.seed = store, body, int(seed)
        self._last: tuple[str, Any] | None = None

    def __getattr__(self, name: str) -> Any:
        if name in ("store", "body", "seed", "_last"):  # not yet set (copy, pickle): no recursion
            raise AttributeError(name)
        return getattr(self.store, name)

    def betas(self, clip_id: str, num_betas: int = 10) -> torch.Tensor:
        """Clip ``clip_id``'s wearer, ``(num_betas,)`` (:func:`heldout_betas`)."""
        return heldout_betas(clip_id, self.seed, num_betas)

    def load(self, clip_id: str) -> Any:
        """The clip (:class:`~wearpose.motion.MotionSequence`) on its wearer: betas
        :meth:`betas`, root re-fitted (:func:`wearpose.motion.refit_to_body`)."""
        from wearpose.motion import refit_to_body  # start-up: motion adds ~91 ms to import this module

        if self._last is None or self._last[0] != clip_id:
            motion = self.store.load(clip_id)
            self._last = (clip_id, refit_to_body(motion, self.body, self.betas(clip_id, int(motion.betas.shape[-1]))))
        return self._last[1]


def wearer_store(store: Any, bodies: str, body: Any, seed: int) -> Any:
    """The store a protocol reads its clips from for ``bodies`` (:data:`BODIES`): ``store``
    itself for ``"corpus"``, a :class:`WearerStore` over it for ``"heldout"``. ``body``: the
    :class:`~wearpose.body.BodyModel` the clips are re-fitted on (the models' own; the default
    asset when the model has none, as BiRAE)."""
    if check_bodies(bodies) == "corpus":
        return store
    if body is None:
        from wearpose.body import BodyModel  # start-up: body adds ~57 ms to import this module

        body = BodyModel()
    return WearerStore(store, body, seed)


def wearers(bodies: str) -> str:
    """How the clips' wearers were chosen, for a table's caption."""
    return ("wearers: a held-out body shape per clip (`--bodies heldout`, seed namespace `eval-body`), the clip "
            "re-fitted to it" if bodies == "heldout" else "wearers: the clips' own body (beta = 0)")


def clip_bodies(store: Any, clip_ids: list[str]) -> dict[str, list[float]]:
    """``{clip id: betas}`` of the clips' wearers in ``store`` (a :class:`WearerStore`; ``{}``
    for any other store: the clips' own bodies), rounded to 1e-4 for the result files."""
    if not isinstance(store, WearerStore):
        return {}
    return {cid: [round(float(b), 4) for b in store.betas(cid)] for cid in clip_ids}


__all__ = ["BODIES", "BODY_NAMESPACE", "WearerStore", "check_bodies", "clip_bodies", "heldout_betas", "wearer_store", "wearers"]

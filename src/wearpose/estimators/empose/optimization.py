"""EM-POSE optimisation baseline (main paper Sec. 6.2, "Optimization"): per-frame L-BFGS with a
strong-Wolfe line search on the reconstruction loss L_r (Eq. 6) plus pose and shape priors.

The paper uses VPoser as pose prior; VPoser is not available here, so we train our own small
pose-prior VAE on the corpus train split (:class:`PosePriorVAE`: the 6D rotations of the 19
estimated body joints, MLP encoder/decoder 256 wide, 32-D latent, Gaussian prior; KL weight
:data:`KL_WEIGHT`). As with VPoser, the pose is optimised in the latent space:

    min_{z, beta}  L_r(decode(z), beta) + lambda_z ||z||^2 + lambda_beta ||beta||^2

L_r does not depend on the root orientation (the measurements are relative to the EM source,
which rides on the body), so the root is set after the fit so that the body's source site
coincides with the source frame. Every frame is warm-started from the previous one (tracking). ``torch.optim.LBFGS(line_search_fn="strong_wolfe")``, ``max_iter`` iterations per
frame. Slow by nature (an optimisation per frame): evaluate on a subset.

Train the prior: ``wearpose train poseprior --out runs/poseprior_cpu``
(writes ``prior.pt``, an ``empose-lbfgs`` checkpoint for kit ``em12`` holding the VAE).
"""

from __future__ import annotations

import math
from typing import Any, Callable, Mapping

import torch
from torch import nn

from wearpose.estimators.base import PoseFrame, PoseTrack, SensorFrame
from wearpose.estimators.empose.config import EmposeConfig
from wearpose.estimators.empose.estimator import EmposeEstimator
from wearpose.estimators.method import TrainRun
from wearpose.estimators.empose.model import PRED_JOINTS, decode_omega, reconstruction_loss
from wearpose.estimators.registry import register_estimator
from wearpose.geometry import matrix_to_rot6d
from pathlib import Path
from wearpose.body import BodyModel
from wearpose.estimators.empose.data import build_split

BODY_JOINTS = tuple(j for j in PRED_JOINTS if j != 0)  # the 19 joints the prior models
LATENT = 32
KL_WEIGHT = 5e-3
LAMBDA_Z = 1e-3  #: weight of ||z||^2 (L_r is in m^2 + Frobenius^2 summed over sensors)
LAMBDA_BETA = 1e-3


class PosePriorVAE(nn.Module):
    """VAE over the 6D rotations of :data:`BODY_JOINTS` (19 x 6 = 114 numbers)."""

    def __init__(self, width: int = 256, latent: int = LATENT) -> None:
        super().__init__()
        D = len(BODY_JOINTS) * 6
        self.enc = nn.Sequential(nn.Linear(D, width), nn.LeakyReLU(0.1), nn.Linear(width, width), nn.LeakyReLU(0.1),
                                 nn.Linear(width, 2 * latent))
        self.dec = nn.Sequential(nn.Linear(latent, width), nn.LeakyReLU(0.1), nn.Linear(width, width), nn.LeakyReLU(0.1),
                                 nn.Linear(width, D))
        self.latent = latent

    def encode(self, pose6: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        mu, logvar = self.enc(pose6).chunk(2, -1)
        return mu, logvar.clamp(-10, 5)

    def decode(self, z: torch.Tensor) -> torch.Tensor:
        """``(..., latent)`` -> 6D rotations ``(..., 19 * 6)`` (unnormalised; Gram-Schmidt downstream)."""
        return self.dec(z)

    def loss(self, pose6: torch.Tensor, g: torch.Generator) -> tuple[torch.Tensor, dict[str, float]]:
        mu, logvar = self.encode(pose6)
        z = mu + torch.randn(mu.shape, generator=g) * (0.5 * logvar).exp()
        rec = ((self.decode(z) - pose6) ** 2).sum(-1).mean()
        kl = (-0.5 * (1 + logvar - mu ** 2 - logvar.exp()).sum(-1)).mean()
        return rec + KL_WEIGHT * kl, {"rec": float(rec.detach()), "kl": float(kl.detach())}


def train_pose_prior(out_dir: str, epochs: int = 4, batch: int = 256, lr: float = 1e-3, seed: int = 0,
                     limit: int | None = None, store: Any = None, cache_root: Any = None, train_command: str = "",
                     log: Callable[[str], None] = print) -> dict[str, Any]:
    """Train :class:`PosePriorVAE` on the train split's poses (the EM-POSE cached data), pick the
    epoch with the lowest validation reconstruction error, save ``<out>/prior.pt`` (its
    ``train_command``: ``train_command``, else the equivalent ``wearpose train poseprior``);
    ``log`` receives one line per epoch."""


    torch.manual_seed(seed)
    cfg = EmposeConfig.preset("cpu", 12)
    body = BodyModel()
    tr = build_split("train", cfg, body, limit=limit, store=store, cache_root=cache_root)
    va = build_split("val", cfg, body, limit=cfg.val_clips, store=store, cache_root=cache_root)
    sel = list(BODY_JOINTS)
    xt, xv = tr.pose6[:, sel].flatten(1), va.pose6[:, sel].flatten(1)
    est = LbfgsEstimator(cfg.override(model="lgd"), body=body)
    vae = est.model
    opt = torch.optim.Adam(vae.parameters(), lr=lr)
    g = torch.Generator().manual_seed(seed)
    best, hist = math.inf, []
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    for ep in range(epochs):
        perm = torch.randperm(len(xt), generator=g)
        vae.train()
        for i in range(0, max(1, len(xt) - batch + 1), batch):
            loss, _ = vae.loss(xt[perm[i:i + batch]], g)
            opt.zero_grad()
            loss.backward()
            opt.step()
        vae.eval()
        with torch.no_grad():
            mu, _ = vae.encode(xv)
            val = float(((vae.decode(mu) - xv) ** 2).sum(-1).mean())
        hist.append({"epoch": ep + 1, "val_rec": val})
        log(f"epoch {ep + 1}: val reconstruction {val:.5f}")
        if val < best:
            best = val
            est.data_fingerprint = tr.fingerprint
            est.train_command = train_command or f"wearpose train poseprior --out {out_dir} --epochs {epochs}"
            est.meta.update({"epoch": ep + 1, "val_rec": val, "prior": "PosePriorVAE (ours; VPoser unavailable)"})
            est.save(out / "prior.pt")
    return {"best_val_rec": best, "history": hist}


@register_estimator("empose-lbfgs")
class LbfgsEstimator(EmposeEstimator):
    """L-BFGS optimisation baseline (module doc). ``self.model`` is the pose prior."""

    name = "empose-lbfgs"
    causal = True
    lookahead = 0

    def __init__(self, config: EmposeConfig | None = None, body: Any = None, device: str | torch.device = "cpu",
                 max_iter: int = 20) -> None:
        super().__init__(config, body=body, device=device)
        self.model = PosePriorVAE().to(self.device)
        self.max_iter = max_iter
        self.every = 1
        self._warm: tuple[torch.Tensor, ...] | None = None

    @classmethod
    def training_data_description(cls, config: Mapping[str, Any]) -> str | None:
        """None: no network sees simulated sensors here (the pose prior is fitted to corpus poses),
        so the inherited EM sentence would be wrong; ship with ``--simulation``."""
        return None

    def _solve(self, p: torch.Tensor, R: torch.Tensor, offR: torch.Tensor, offt: torch.Tensor,
               warm: tuple[torch.Tensor, ...] | None) -> tuple[torch.Tensor, torch.Tensor, tuple[torch.Tensor, ...], float]:
        """One frame: p ``(S, 3)``, R ``(S, 3, 3)`` -> local_rot ``(24, 3, 3)``, betas ``(10,)``."""
        dev = self.device
        if warm is None:
            warm = (torch.zeros(1, LATENT, device=dev), matrix_to_rot6d(torch.eye(3, device=dev))[None],
                    torch.zeros(1, 10, device=dev))
        z, r, b = (w.detach().clone().requires_grad_(True) for w in warm)
        r.requires_grad_(False)  # L_r does not see the root (below)
        opt = torch.optim.LBFGS([z, b], lr=1.0, max_iter=self.max_iter, line_search_fn="strong_wolfe")

        def omega() -> torch.Tensor:
            return torch.cat([r, self.model.decode(z), b], -1)  # root first: PRED_JOINTS order

        def closure() -> torch.Tensor:
            opt.zero_grad()
            Rl, beta = decode_omega(omega(), "rot6d")
            ph, Rh, _ = self.sensors(Rl, beta, offR[None], offt[None])
            loss = reconstruction_loss(ph, Rh, p[None], R[None]).sum() + LAMBDA_Z * (z ** 2).sum() \
                + LAMBDA_BETA * (b ** 2).sum()
            loss.backward()
            return loss

        with torch.enable_grad():
            opt.step(closure)
        with torch.no_grad():
            om = omega()
            Rl, beta = decode_omega(om, "rot6d")
            # Measurements are relative to the source, which rides on the body: L_r is invariant
            # to the root orientation. The root is the one that puts the body's own source site
            # at the identity of the source frame (what the measurements are expressed in).
            src = self.sites["<em_source>"]
            R_site = self.body.sites(Rl, beta, None, [src]).rotations[:, 0]
            Rl[:, 0] = R_site.transpose(-1, -2) @ Rl[:, 0]
            ph, Rh, _ = self.sensors(Rl, beta, offR[None], offt[None])
            rec = float(reconstruction_loss(ph, Rh, p[None], R[None])[0])
        return Rl[0], beta[0], (z.detach(), r.detach(), b.detach()), rec

    @torch.no_grad()
    def estimate(self, recording: Any, every: int | None = None) -> PoseTrack:
        """Offline = the online tracker over the recording. ``every`` (default ``self.every``, 1):
        solve only every ``every``-th frame (warm-started from the previous solved one); the
        frames in between repeat the last solution and are marked ``valid = False`` so that
        evaluations score solved frames only."""
        every = every or self.every
        p, R, valid = self._measurements(recording)
        offR, offt = self._offsets_from(recording)
        self.model.eval()
        T = p.shape[0]
        rots, betas, recs = [], [], []
        warm, last = None, None
        for t in range(T):
            if last is None or t % every == 0:
                rot, beta, warm, rec = self._solve(p[t].to(self.device), R[t].to(self.device), offR.to(self.device),
                                                   offt.to(self.device), warm)
                last = (rot.cpu(), beta.cpu(), rec)
            rots.append(last[0])
            betas.append(last[1])
            recs.append(last[2])
        b_all = torch.stack(betas)
        ok = valid.all(1)
        if every > 1:
            ok = ok & (torch.arange(T) % every == 0)
        return PoseTrack(torch.stack(rots), (b_all[ok] if bool(ok.any()) else b_all).mean(0), None, ok, self.fps,
                         extras={"frame": "em_source", "method": self.name, "rec_loss": torch.tensor(recs),
                                 "betas_per_frame": b_all})

    def reset(self) -> None:
        super().reset()
        self._warm = None

    @torch.no_grad()
    def step(self, frame: SensorFrame) -> PoseFrame:
        """One frame, warm-started from the previous solution."""
        if self._offsets is None:
            self._offsets = self._offsets_from(None)
        (p, R), v = self._input(frame)
        self.model.eval()
        offR, offt = self._offsets
        rot, beta, self._warm, rec = self._solve(p.to(self.device), R.to(self.device), offR.to(self.device),
                                                 offt.to(self.device), self._warm)
        return PoseFrame(rot.cpu(), beta.cpu(), None, bool(v.all()), frame.timestamp,
                         extras={"frame": "em_source", "rec_loss": rec})


def train_from_options(opts: Mapping[str, Any], run: TrainRun) -> dict[str, Any]:
    """``wearpose train poseprior``: :func:`train_pose_prior` with ``--epochs`` on ``--limit``
    training clips (all when not given), ``--threads`` torch CPU threads; writes
    ``<out>/prior.pt``, the ``empose-lbfgs`` checkpoint that holds the VAE.

    Returns:
        :func:`train_pose_prior`'s result with ``method`` and ``out_dir``.
    """
    if run.threads is not None:
        torch.set_num_threads(run.threads)
    out = run.out if run.out is not None else "runs/poseprior_cpu"
    log = (lambda s: None) if run.quiet else (lambda s: print(s, flush=True))
    res = train_pose_prior(str(out), epochs=run.epochs, limit=run.limit, train_command=run.train_command, log=log)
    return {"method": "empose-lbfgs", "out_dir": str(out), **res}

"""BiRAE uncertainty (Sec. IV-D, IV-F, V-F): aleatoric head, MC-dropout epistemic part, their
combination, post-hoc sigma-scaling calibration and calibration statistics.

- aleatoric: ``sigma_a = exp(logvar / 2)`` from the log-variance head (trained by Eq. 6);
- epistemic (Eq. 7): the variance of the mean over ``M`` MC-dropout passes;
- combined (Eq. 8): ``sigma^2 = sigma_e^2 + mean_i sigma_a,i^2``; the reported mean is the MC mean;
- calibration (Laves et al. 2020, cited by the paper): one scalar ``s`` multiplying sigma, fitted
  on validation data. ``method="nll"`` is Laves' maximum-likelihood fit,
  ``s^2 = mean((y - mu)^2 / sigma^2)``; ``method="quantile"`` picks ``s`` so that exactly 68.27 %
  of the validation residuals satisfy ``|y - mu| <= s sigma`` (robust to heavy tails).

Everything is per exp-map component (radians), which is where the model's Gaussian lives: the
"per-joint errors inside +-1 sigma" of the paper's Figs. 7-10 are the three components of a
joint's exp-map, each against its own sigma.
"""

from __future__ import annotations

import math
from typing import Any

import torch

from wearpose.body.skeleton import MAJOR_JOINTS
from wearpose.evaluate.metrics import BIRAE_JOINT_GROUPS

#: Fraction of a Gaussian within +-1 / +-2 sigma.
GAUSS_1SIGMA = math.erf(1 / math.sqrt(2))
GAUSS_2SIGMA = math.erf(2 / math.sqrt(2))


@torch.no_grad()
def mc_predict(model: Any, x: torch.Tensor, samples: int, lengths: torch.Tensor | None = None,
               generator: torch.Generator | None = None, chunk: int = 8) -> tuple[torch.Tensor, torch.Tensor]:
    """``samples`` MC-dropout passes (Eq. 7) of ``x`` ``(B, T, D)``, batched ``chunk`` at a time.

    Returns:
        ``mu`` and ``logvar``, each ``(M, B, T, 45)``.
    """
    model.eval()
    B = x.shape[0]
    mus, lvs = [], []
    for a in range(0, samples, chunk):
        m = min(chunk, samples - a)
        xr = x.repeat(m, 1, 1)
        lr = lengths.repeat(m) if lengths is not None else None
        out = model(xr, lr, mc=True, generator=generator)
        mus.append(out["mu"].reshape(m, B, *out["mu"].shape[1:]))
        lvs.append(out["logvar"].reshape(m, B, *out["logvar"].shape[1:]))
    return torch.cat(mus), torch.cat(lvs)


def combine(mus: torch.Tensor, logvars: torch.Tensor) -> dict[str, torch.Tensor]:
    """Eq. 7-8 over the leading MC axis: ``mu``, ``sigma`` (combined), ``sigma_a``, ``sigma_e``."""
    mu = mus.mean(0)
    var_e = ((mus - mu) ** 2).mean(0)
    var_a = torch.exp(logvars).mean(0)
    return {"mu": mu, "sigma": (var_e + var_a).sqrt(), "sigma_a": var_a.sqrt(), "sigma_e": var_e.sqrt()}


def fit_sigma_scale(residual: torch.Tensor, sigma: torch.Tensor, method: str = "nll") -> float:
    """Scalar ``s`` so that ``s * sigma`` is calibrated on these residuals (module doc).

    Args:
        residual: ``(N,)`` ``y - mu`` (any shape, flattened), radians.
        sigma: same shape, > 0.
        method: ``"nll"`` (Laves et al.) or ``"quantile"``.
    """
    r = residual.reshape(-1).double()
    s = sigma.reshape(-1).double().clamp_min(1e-9)
    z = (r / s).abs()
    if method == "nll":
        return float(torch.sqrt((z ** 2).mean()))
    if method == "quantile":
        return float(torch.quantile(z, GAUSS_1SIGMA)) if z.numel() <= 16_000_000 else float(z.sort().values[
            int(GAUSS_1SIGMA * (z.numel() - 1))])
    raise ValueError(f"fit_sigma_scale: method must be 'nll' or 'quantile', got {method!r}")


def coverage(residual: torch.Tensor, sigma: torch.Tensor, k: float = 1.0) -> float:
    """Fraction of ``|residual| <= k * sigma`` (elementwise, all entries)."""
    return float(((residual.abs() <= k * sigma).double()).mean())


def calibration_report(residual: torch.Tensor, sigma: torch.Tensor, groups: dict[str, list[int]] | None = None,
                       joint_error: torch.Tensor | None = None, joint_sigma: torch.Tensor | None = None
                       ) -> dict[str, Any]:
    """Coverage of +-1 / +-2 sigma overall and per joint group, and Pearson r of sigma vs error.

    Args:
        residual, sigma: ``(N, 15, 3)`` per exp-map component, radians (major-joint order).
        groups: name -> positions in the 15 major joints (default: BiRAE's distal / tracking /
            other groups).
        joint_error, joint_sigma: optional ``(N, 15)`` per-joint geodesic error and per-joint
            sigma for the correlation (default: per component ``|residual|`` vs sigma).
    """
    groups = groups or major_groups()
    out: dict[str, Any] = {"within_1sigma": coverage(residual, sigma, 1.0), "within_2sigma": coverage(residual, sigma, 2.0),
                           "gaussian_1sigma": GAUSS_1SIGMA, "gaussian_2sigma": GAUSS_2SIGMA, "groups": {}}
    for g, idx in groups.items():
        out["groups"][g] = {"within_1sigma": coverage(residual[:, idx], sigma[:, idx], 1.0),
                            "within_2sigma": coverage(residual[:, idx], sigma[:, idx], 2.0),
                            "mean_sigma_deg": math.degrees(float(sigma[:, idx].mean())),
                            "mean_abs_error_deg": math.degrees(float(residual[:, idx].abs().mean()))}
    e = residual.abs().reshape(-1) if joint_error is None else joint_error.reshape(-1)
    s = sigma.reshape(-1) if joint_sigma is None else joint_sigma.reshape(-1)
    out["pearson_r_sigma_error"] = pearson(s, e)
    if joint_error is not None:
        out["pearson_r_per_component"] = pearson(sigma.reshape(-1), residual.abs().reshape(-1))
    return out


def pearson(a: torch.Tensor, b: torch.Tensor) -> float:
    """Pearson correlation of two flat tensors (NaN if either is constant)."""
    a, b = a.double().reshape(-1), b.double().reshape(-1)
    a, b = a - a.mean(), b - b.mean()
    den = float(a.norm() * b.norm())
    return float((a * b).sum()) / den if den > 0 else math.nan


def reliability_curve(residual: torch.Tensor, sigma: torch.Tensor, levels: torch.Tensor | None = None
                      ) -> dict[str, list[float]]:
    """Observed vs expected fraction inside the Gaussian central interval of each confidence level."""
    levels = levels if levels is not None else torch.linspace(0.05, 0.95, 19, dtype=torch.float64)
    z = (residual.abs() / sigma.clamp_min(1e-9)).reshape(-1).double()
    k = torch.special.ndtri(0.5 + levels / 2)
    obs = [(z <= float(kk)).double().mean().item() for kk in k]
    return {"expected": [float(x) for x in levels], "observed": obs}


def major_groups() -> dict[str, list[int]]:
    """BiRAE's joint groups as positions in :data:`wearpose.body.MAJOR_JOINTS` order."""
    pos = {j: i for i, j in enumerate(MAJOR_JOINTS)}
    return {g: [pos[j] for j in js] for g, js in BIRAE_JOINT_GROUPS.items()}

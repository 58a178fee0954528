"""EM dipole field, induced coil voltages, and metal as induced secondary dipoles.

**Source and sensor** (EM-POSE Eq. 1-2). Three orthogonal source coils ``k`` with moments
``M_k`` (the source frame's axes) and three orthogonal sensor coils ``l`` with axes ``N_l``
(the sensor frame's axes). Eq. 1 gives the quasi-static field of coil ``k`` at ``p``::

    B_k(p) = mu0 / (4 pi) [3 (M_k . p) p / |p|^5 - M_k / |p|^3]

and Eq. 2 the voltage of sensor coil ``l``: ``V_kl = -j w_k n a B_k(p) . (R N_l)``. After the
tracker's synchronous demodulation the carrier ``exp(-j w t)`` and the constant ``-j w n a``
are one known gain; we work in normalised units where ``mu0 |M| w n a / (4 pi) = 1`` so that::

    V = R^T D(p),      D(r) = (3 r_hat r_hat^T - I) / |r|^3          (3 x 3; V[l, k])

(rows: sensor coils, columns: source coils; |V| ~ 2 at 1 m on a coil axis).

**Metal** (our model, documented physics): a conductive object in an AC field carries eddy
currents whose far field is a magnetic dipole proportional to the local primary field
(Born/first-order scattering; no coupling between objects). For an object at ``c`` with
polarisability tensor ``A`` (m^3, in these normalised units ``m_ind = A D(c - s) M_k``), its
field at the sensor is ``D(p - c) A D(c - s) M_k``. Eddy currents oppose the field, so ``A`` is
negative definite on the directions where currents can flow (quasi-static high-frequency
limit, in-phase part as the tracker demodulates it):

- sphere of radius ``a``: ``A = -eta a^3 / 2 I`` (perfect conductor: ``m = -2 pi a^3 H``);
- thin disk / plate of radius ``a``, normal ``n``: ``A = -eta (2 / 3 pi) a^3 n n^T``
  (perfect conducting disk: ``m = -(8/3) a^3 H_n``); a large plate is a grid of such disks;
- rod (desk leg, door frame) of radius ``rho`` along ``t``: per unit length ``-2 pi rho^2``
  transverse (conducting cylinder), cut into short segments of ``A = -eta rho^2 L_seg / 2 (I - t t^T)``.

``eta`` in [0, 1] is the efficiency of the eddy-current response at the operating frequency
(1 = perfect conductor). Since ``D`` falls as ``r^-3``, a small object perturbs the sensor's
field by about ``a^3 |p|^3 / (|c - s|^3 |p - c|^3)``: the ``1/r^3`` fall-off with the
sensor-to-object distance that makes passing an object a spike.

**Floor** (steel rebar, "as a typical building, the floor has steel support", MI-Poser fn. 3):
a conducting plane's boundary condition (normal field zero) is met by an image source mirrored
in the plane with moment ``(I - 2 n n^T) M_k``, scaled by a reflection coefficient ``eta_floor``.

All arrays are numpy float64, world frame (Y up) unless said otherwise.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from wearpose.errors import ConfigError, ShapeError

#: mu0 / (4 pi), T m / A (for the unnormalised Eq. 1 in :func:`dipole_field`).
MU0_4PI = 1e-7


def dipole_field(r: np.ndarray, m: np.ndarray) -> np.ndarray:
    """EM-POSE Eq. 1 (magnitude, SI): field of a dipole ``m`` (A m^2) at offset ``r`` (m), tesla.

    Args:
        r: ``(..., 3)`` offset from the dipole; m: ``(..., 3)`` moment (broadcast).
    """
    r = np.asarray(r, dtype=np.float64)
    m = np.asarray(m, dtype=np.float64)
    n = np.linalg.norm(r, axis=-1, keepdims=True)
    mr = np.sum(m * r, axis=-1, keepdims=True)
    return MU0_4PI * (3.0 * mr * r / n ** 5 - n ** 2 * m / n ** 5)


def coupling(r: np.ndarray) -> np.ndarray:
    """Normalised dipole coupling ``D(r) = (3 r_hat r_hat^T - I) / |r|^3``: ``(..., 3)`` -> ``(..., 3, 3)``.

    ``D(r) M`` is the (normalised) field at ``r`` of a unit dipole along ``M`` at the origin.
    """
    r = np.asarray(r, dtype=np.float64)
    if r.shape[-1] != 3:
        raise ShapeError(f"coupling: expected (..., 3), got {r.shape}")
    n2 = np.sum(r * r, axis=-1)[..., None, None]
    n = np.sqrt(n2)
    outer = r[..., :, None] * r[..., None, :]
    return (3.0 * outer / n2 - np.eye(3)) / n ** 3


def soft_coupling(r: np.ndarray, soft: np.ndarray) -> np.ndarray:
    """:func:`coupling` with a softening length: ``|r|^2 -> |r|^2 + soft^2``.

    A small dipole standing in for a finite patch of metal (a grid cell of a plate, a rod
    segment) must not blow up when the sensor comes closer than the patch's own size; softening
    by the patch radius keeps the perturbation finite (order one at contact, as for a real
    plate whose eddy currents cancel the normal field at its surface) and leaves it unchanged
    at distances well above the patch size.

    Args:
        r: ``(..., 3)``; soft: broadcastable to ``r.shape[:-1]``, m.
    """
    r = np.asarray(r, dtype=np.float64)
    n2 = np.sum(r * r, axis=-1) + np.asarray(soft, dtype=np.float64) ** 2
    n2 = n2[..., None, None]
    outer = r[..., :, None] * r[..., None, :]
    return (3.0 * outer / n2 - np.eye(3)) / (n2 * np.sqrt(n2))


def ideal_voltages(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Voltages of a sensor at ``(R, p)`` in the source frame, no metal: ``V = R^T D(p)``.

    Args:
        R: ``(..., 3, 3)`` sensor orientation (sensor -> source frame); p: ``(..., 3)`` m.

    Returns:
        ``(..., 3, 3)``: ``V[..., l, k]`` = sensor coil ``l``, source coil ``k``.
    """
    return np.swapaxes(R, -1, -2) @ coupling(p)


def sphere_polarisability(radius: float, eta: float = 1.0) -> np.ndarray:
    """``A`` of a conducting sphere (module doc), m^3."""
    return -eta * radius ** 3 / 2.0 * np.eye(3)


def disk_polarisability(radius: float, normal: Sequence[float], eta: float = 1.0) -> np.ndarray:
    """``A`` of a thin conducting disk with unit ``normal`` (module doc), m^3."""
    n = np.asarray(normal, dtype=np.float64)
    n = n / np.linalg.norm(n)
    return -eta * (2.0 / (3.0 * np.pi)) * radius ** 3 * np.outer(n, n)


def rod_polarisability(radius: float, length: float, axis: Sequence[float], eta: float = 1.0) -> np.ndarray:
    """``A`` of a conducting rod segment (transverse eddy currents, module doc), m^3."""
    t = np.asarray(axis, dtype=np.float64)
    t = t / np.linalg.norm(t)
    return -eta * radius ** 2 * length / 2.0 * (np.eye(3) - np.outer(t, t))


@dataclass
class MetalObject:
    """A metal object: one or more induced dipoles.

    Attributes:
        name: label (e.g. ``"laptop"``).
        points: ``(K, 3)`` dipole centres, m: world frame for a static object, the carrier's
            sensor frame for a carried one.
        tensors: ``(K, 3, 3)`` polarisabilities ``A`` in the same frame, m^3.
        soft: ``(K,)`` size of the patch each dipole stands for, m (:func:`soft_coupling`).
        carrier: ``None`` (static in the room) or the name of the sensor site carrying it
            (e.g. a can held in that hand).
        active: ``None`` (always present) or ``(T,)`` bool mask of the frames it is present
            (a carried object is picked up and put down).
    """

    name: str
    points: np.ndarray
    tensors: np.ndarray
    soft: np.ndarray | float = 0.0
    carrier: str | None = None
    active: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.points = np.asarray(self.points, dtype=np.float64).reshape(-1, 3)
        self.tensors = np.asarray(self.tensors, dtype=np.float64).reshape(-1, 3, 3)
        self.soft = np.broadcast_to(np.asarray(self.soft, dtype=np.float64), (self.points.shape[0],)).copy()
        if self.points.shape[0] != self.tensors.shape[0]:
            raise ShapeError(f"MetalObject {self.name!r}: {self.points.shape[0]} points but {self.tensors.shape[0]} tensors")

    @staticmethod
    def sphere(name: str, centre: Sequence[float], radius: float, eta: float = 1.0, **kw) -> MetalObject:
        return MetalObject(name, np.asarray(centre, dtype=np.float64)[None], sphere_polarisability(radius, eta)[None],
                           soft=0.0, **kw)

    @staticmethod
    def plate(name: str, centre: Sequence[float], normal: Sequence[float], size: tuple[float, float],
              eta: float = 1.0, cell: float = 0.1, **kw) -> MetalObject:
        """A rectangular plate ``size = (width, height)`` m as a grid of disks of pitch ``<= cell``."""
        n = np.asarray(normal, dtype=np.float64)
        n = n / np.linalg.norm(n)
        ref = np.array([0.0, 1.0, 0.0]) if abs(n[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
        u = np.cross(ref, n)
        u /= np.linalg.norm(u)
        v = np.cross(n, u)
        nu, nv = max(1, int(np.ceil(size[0] / cell))), max(1, int(np.ceil(size[1] / cell)))
        du, dv = size[0] / nu, size[1] / nv
        # equal-area disk per cell: pi a^2 = du dv
        a = np.sqrt(du * dv / np.pi)
        gu = (np.arange(nu) + 0.5) * du - size[0] / 2
        gv = (np.arange(nv) + 0.5) * dv - size[1] / 2
        pts = np.asarray(centre, dtype=np.float64) + gu[:, None, None] * u + gv[None, :, None] * v
        pts = pts.reshape(-1, 3)
        A = np.repeat(disk_polarisability(a, n, eta)[None], len(pts), axis=0)
        return MetalObject(name, pts, A, soft=a, **kw)

    @staticmethod
    def rod(name: str, start: Sequence[float], end: Sequence[float], radius: float, eta: float = 1.0,
            segment: float = 0.05, **kw) -> MetalObject:
        a, b = np.asarray(start, dtype=np.float64), np.asarray(end, dtype=np.float64)
        L = float(np.linalg.norm(b - a))
        k = max(1, int(np.ceil(L / segment)))
        s = (np.arange(k) + 0.5) / k
        pts = a + s[:, None] * (b - a)
        A = np.repeat(rod_polarisability(radius, L / k, b - a, eta)[None], k, axis=0)
        return MetalObject(name, pts, A, soft=max(radius, L / k / 2), **kw)


@dataclass
class Scene:
    """Metal around an EM system: objects plus an optional conducting floor.

    Attributes:
        objects: :class:`MetalObject` list.
        floor_height: world ``y`` of the floor, m (``None`` = no floor).
        floor_reflection: image-source coefficient ``eta_floor`` in [0, 1].
    """

    objects: list[MetalObject] = field(default_factory=list)
    floor_height: float | None = None
    floor_reflection: float = 0.0

    def field_matrix(self, sensor_p: np.ndarray, src_R: np.ndarray, src_p: np.ndarray,
                     carriers: dict[str, tuple[np.ndarray, np.ndarray]] | None = None,
                     include_primary: bool = True) -> np.ndarray:
        """Normalised field of the three source coils at the sensor, world frame.

        Args:
            sensor_p: ``(T, 3)`` sensor position, m, world.
            src_R: ``(T, 3, 3)`` source orientation (its columns are the coil moments ``M_k``).
            src_p: ``(T, 3)`` source position.
            carriers: site name -> ``(R (T, 3, 3), p (T, 3))`` world poses of carrier sites
                (for carried objects).
            include_primary: add the direct source field (False: metal and floor only).

        Returns:
            ``(T, 3, 3)`` ``H[:, :, k]`` = field of coil ``k`` at the sensor (world axes).
        """
        H = coupling(sensor_p - src_p) @ src_R if include_primary else np.zeros((sensor_p.shape[0], 3, 3))
        for ob in self.objects:
            if ob.carrier is None:
                pts = np.broadcast_to(ob.points[None], (sensor_p.shape[0], *ob.points.shape))
                A = np.broadcast_to(ob.tensors[None], (sensor_p.shape[0], *ob.tensors.shape))
            else:
                if carriers is None or ob.carrier not in carriers:
                    raise ConfigError(f"Scene: object {ob.name!r} is carried by {ob.carrier!r}, whose pose was not given")
                cR, cp = carriers[ob.carrier]
                pts = cp[:, None] + np.einsum("tij,kj->tki", cR, ob.points)
                A = np.einsum("tij,kjl,tml->tkim", cR, ob.tensors, cR)
            # induced moment per coil: A D(c - s) M ; its field at the sensor: D(p - c) m
            Dcs = coupling(pts - src_p[:, None])                      # (T, K, 3, 3)
            Dpc = soft_coupling(sensor_p[:, None] - pts, ob.soft)     # (T, K, 3, 3)
            contrib = (Dpc @ A @ Dcs).sum(axis=1) @ src_R             # (T, 3, 3)
            if ob.active is not None:
                contrib = contrib * np.asarray(ob.active, dtype=np.float64)[:, None, None]
            H = H + contrib
        if self.floor_height is not None and self.floor_reflection > 0:
            n = np.array([0.0, 1.0, 0.0])
            img = src_p.copy()
            img[:, 1] = 2 * self.floor_height - src_p[:, 1]
            Mirror = np.eye(3) - 2 * np.outer(n, n)
            H = H + self.floor_reflection * (coupling(sensor_p - img) @ Mirror @ src_R)
        return H


def measured_voltages(scene: Scene, sensor_R: np.ndarray, sensor_p: np.ndarray, src_R: np.ndarray,
                      src_p: np.ndarray, carriers: dict[str, tuple[np.ndarray, np.ndarray]] | None = None,
                      noise: float = 0.0, rng: np.random.Generator | None = None) -> np.ndarray:
    """Voltages ``(T, 3, 3)`` (``V[t, l, k]``) of a sensor in a scene, with white voltage noise.

    ``V = R_WS^T H`` where ``H`` is :meth:`Scene.field_matrix` (world). Without metal this equals
    :func:`ideal_voltages` of the sensor pose relative to the source.

    Args:
        noise: std of the additive white noise per voltage (normalised units).
    """
    H = scene.field_matrix(sensor_p, src_R, src_p, carriers)
    V = np.swapaxes(sensor_R, -1, -2) @ H
    if noise > 0:
        rng = rng if rng is not None else np.random.default_rng(0)
        V = V + noise * rng.standard_normal(V.shape)
    return V

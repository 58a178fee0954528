"""Condition presets and :func:`simulate_condition`: EM tracking of body-worn sensors among metal.

Pipeline per sensor (all physics, nothing painted on the output):

1. true sensor and source poses from the motion (:mod:`.trajectories`; the source rides on the
   head as in MI-Poser, or is fixed in the room);
2. a scene (:class:`~wearpose.interference.field.Scene`) drawn for the condition: a conducting
   floor, static objects placed along the path the sensor actually takes (so that it passes
   them at a drawn closest distance, as a hand passes a desk, a laptop or a door), and for the
   "extreme" condition objects carried in the hand for several seconds;
3. the 9 coil voltages (:func:`~wearpose.interference.field.measured_voltages`) with white
   voltage noise and a per-session sensor-coil calibration error (gains, axis misalignment);
4. the pose solved from the voltages by :class:`~wearpose.interference.tracker.EMTracker`
   (warm-started least squares, hemisphere by continuity);
5. a co-located IMU at 120 Hz: the relative motion of the sensor with respect to the source
   run through :func:`wearpose.sensors.simulate_imu` with its MEMS noise model (white noise,
   turn-on bias, bias walk, orientation noise leaking gravity into the free acceleration).

With a head-worn source the IMU channels are the wrist's motion *relative to the head*: gyro
in the sensor frame, acceleration in the source frame, gravity removed -- what a device gets by
combining the wrist IMU with the glasses' IMU (MI-Poser App. B.2 does the same calibration into
the EMF coordinate with a fixed source).

**Presets** (:data:`CONDITIONS`) follow MI-Poser Sec. 6.1.2: "open-space" (no metal objects
within 2 m, only the steel-reinforced floor), "standard" (desks and rooms with a few everyday
metal objects: laptop, monitor, metal door, desk frame, tools; the hand passes them now and
then) and "extreme" ("we intentionally moved the apparatus closer to metal objects for an
extended period, such as touching a laptop or holding a metal can"). Object sizes are real
object sizes; encounter rates, closest distances, eddy efficiencies and the floor's reflection
coefficient are our choices, tuned on the val split with the room-fixed source of MI-Poser's
User Study 2 (sensor 0.4-1.5 m from it) so that per-session error statistics land in the range
of MI-Poser Table 1 and Table 3's interference ratio (``benchmarks/interference.py`` prints ours
beside theirs). The floor coefficient is 0.1: a rebar mesh under a floor is a grid of loops, far
from a solid conducting plane (0.5 made a metal-free room-fixed session 2-4 cm off at 1-1.5 m).
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, field, replace
from typing import Any, Sequence

import numpy as np
import torch

from wearpose.body import BodyModel
from wearpose.errors import ConfigError
from wearpose.geometry import geodesic_angle
from wearpose.interference.field import MetalObject, Scene, measured_voltages
from wearpose.interference.tracker import EMTracker, TrackerConfig
from wearpose.interference.trajectories import EM_RATE, SiteTrajectories, body_trajectories
from wearpose.sensors.imu import ImuNoise, simulate_imu

#: Voltage noise (normalised units) giving ~0.9 mm RMS position error at 1 m from the source,
#: MI-Poser Sec. 4.1's figure for its tracker in a metal-free lab.
VOLTAGE_NOISE = 1.0e-3


@dataclass(frozen=True)
class ConditionPreset:
    """A metal profile (module doc).

    Attributes:
        name: preset name.
        floor_reflection: image-source coefficient of the floor (0 = none; rebar mesh: 0.1).
        encounters_per_min: static objects placed along each sensor's path per minute.
        closest: ``(min, max)`` closest approach of the path to an object's surface, m.
        catalogue: object kinds drawn for static encounters (see :func:`make_object`).
        carry_fraction: fraction of the time a small object is carried in the hand.
        carry_bout_s: ``(min, max)`` duration of one carrying bout, s.
        carry_offset: ``(min, max)`` distance of the carried object from the sensor, m.
        eta: ``(min, max)`` eddy-current efficiency drawn per object.
        clean_start_s, clean_tolerance: no static object perturbs the field by more than
            ``clean_tolerance`` (relative) during the first ``clean_start_s`` s (sessions start
            clean, as MI-Poser's calibration phase).
        voltage_noise: white voltage noise std (normalised units).
        coil_gain_sigma: per-session std of each sensor coil's gain error (fraction).
        coil_misalign_deg: per-session std of each sensor coil's axis misalignment, degrees.
    """

    name: str
    floor_reflection: float = 0.1
    encounters_per_min: float = 0.0
    closest: tuple[float, float] = (0.05, 0.3)
    catalogue: tuple[str, ...] = ("laptop", "monitor", "door", "desk_leg", "desk_frame", "hammer")
    carry_fraction: float = 0.0
    carry_bout_s: tuple[float, float] = (2.0, 8.0)
    carry_offset: tuple[float, float] = (0.04, 0.1)
    carry_catalogue: tuple[str, ...] = ("can", "phone")
    eta: tuple[float, float] = (0.5, 1.0)
    clean_start_s: float = 0.5
    clean_tolerance: float = 0.01
    voltage_noise: float = VOLTAGE_NOISE
    coil_gain_sigma: float = 0.005
    coil_misalign_deg: float = 0.5


CONDITIONS: dict[str, ConditionPreset] = {
    "open-space": ConditionPreset("open-space"),
    "standard": ConditionPreset("standard", encounters_per_min=35.0, closest=(0.01, 0.15), eta=(0.7, 1.0)),
    "extreme": ConditionPreset("extreme", encounters_per_min=30.0, closest=(0.0, 0.05), eta=(0.8, 1.0), carry_fraction=0.4,
                               carry_offset=(0.01, 0.04), carry_catalogue=("can", "phone", "tablet", "laptop")),
}


def get_condition(condition: str | ConditionPreset) -> ConditionPreset:
    if isinstance(condition, ConditionPreset):
        return condition
    if condition not in CONDITIONS:
        raise ConfigError(f"unknown interference condition {condition!r}; expected one of {sorted(CONDITIONS)} or a ConditionPreset")
    return CONDITIONS[condition]


def _unit(v: np.ndarray) -> np.ndarray:
    return v / max(float(np.linalg.norm(v)), 1e-12)


def make_object(kind: str, anchor: np.ndarray, direction: np.ndarray, gap: float, eta: float,
                rng: np.random.Generator, carrier: str | None = None) -> MetalObject:
    """An everyday metal object whose nearest surface is ``gap`` m from ``anchor`` along ``direction``.

    Kinds and sizes (real object sizes): ``laptop`` (0.33 x 0.23 m plate, lying flat), ``monitor``
    (0.5 x 0.3 m back plate, upright), ``door`` (0.9 x 2.0 m sheet, upright), ``desk_leg``
    (vertical tube, radius 2 cm, 0.72 m), ``desk_frame`` (horizontal tube, 1.2 m), ``hammer``
    (steel head, ~2.5 cm sphere), ``can`` (beverage can, ~3.3 cm sphere), ``phone``
    (0.15 x 0.07 m plate), ``tablet`` (0.25 x 0.17 m plate).
    """
    d = _unit(direction)
    up = np.array([0.0, 1.0, 0.0])
    horiz = _unit(d - up * (d @ up)) if abs(d @ up) < 0.95 else np.array([1.0, 0.0, 0.0])
    if kind == "laptop":
        # lying on a desk under the passing hand
        return MetalObject.plate(kind, anchor - up * gap, up, (0.33, 0.23), eta, cell=0.06, carrier=carrier)
    if kind == "monitor":
        return MetalObject.plate(kind, anchor + horiz * gap, horiz, (0.5, 0.3), eta, cell=0.08, carrier=carrier)
    if kind == "door":
        c = anchor + horiz * gap
        c[1] = 1.0
        return MetalObject.plate(kind, c, horiz, (0.9, 2.0), eta, cell=0.15, carrier=carrier)
    if kind == "desk_leg":
        c = anchor + horiz * (gap + 0.02)
        return MetalObject.rod(kind, [c[0], c[1] - 0.36, c[2]], [c[0], c[1] + 0.36, c[2]], 0.02, eta, carrier=carrier)
    if kind == "desk_frame":
        c = anchor + d * (gap + 0.02)
        t = _unit(np.cross(d, up)) if abs(d @ up) < 0.95 else np.array([1.0, 0.0, 0.0])
        return MetalObject.rod(kind, c - 0.6 * t, c + 0.6 * t, 0.02, eta, segment=0.06, carrier=carrier)
    if kind == "hammer":
        return MetalObject.sphere(kind, anchor + d * (gap + 0.025), 0.025, eta, carrier=carrier)
    if kind == "can":
        return MetalObject.sphere(kind, anchor + d * (gap + 0.033), 0.033, eta, carrier=carrier)
    if kind == "tablet":
        return MetalObject.plate(kind, anchor + d * (gap + 0.004), d, (0.25, 0.17), eta, cell=0.05, carrier=carrier)
    if kind == "phone":
        return MetalObject.plate(kind, anchor + d * (gap + 0.004), d, (0.15, 0.07), eta, cell=0.04, carrier=carrier)
    raise ConfigError(f"make_object: unknown kind {kind!r}")


def draw_scene(preset: ConditionPreset, traj: SiteTrajectories, rng: np.random.Generator,
               floor_height: float = 0.0) -> Scene:
    """A scene for ``traj`` (module doc): floor, encounters along each sensor's path, carried bouts."""
    T, fps = traj.num_frames, traj.fps
    scene = Scene([], floor_height if preset.floor_reflection > 0 else None, preset.floor_reflection)
    minutes = T / fps / 60.0
    P = traj.p.numpy()
    Rw = traj.R.numpy()
    for s, name in enumerate(traj.names):
        n_enc = rng.poisson(preset.encounters_per_min * minutes) if preset.encounters_per_min > 0 else 0
        vel = np.gradient(P[:, s], 1.0 / fps, axis=0) if T > 1 else np.zeros((T, 3))
        # sessions start clean (MI-Poser calibrates on the first seconds "careful not to move the
        # apparatus close to metal objects"): no encounter in the first clean_start_s
        t_min = min(int(preset.clean_start_s * fps), T - 1)
        for _ in range(n_enc):
            t = int(rng.integers(t_min, T))
            # the object sits beside the path: a direction perpendicular to the motion there
            v = vel[t]
            d = rng.standard_normal(3)
            if np.linalg.norm(v) > 1e-3:
                d = d - _unit(v) * (d @ _unit(v))
            gap = float(rng.uniform(*preset.closest))
            kind = str(rng.choice(preset.catalogue))
            ob = make_object(kind, P[t, s], d, gap, float(rng.uniform(*preset.eta)), rng)
            if t_min > 0:
                # it must not disturb the clean start: relative field perturbation there below clean_tolerance
                sl = slice(0, t_min)
                prim = Scene().field_matrix(P[sl, s], traj.src_R.numpy()[sl], traj.src_p.numpy()[sl])
                sec = Scene([ob]).field_matrix(P[sl, s], traj.src_R.numpy()[sl], traj.src_p.numpy()[sl], include_primary=False)
                if float((np.linalg.norm(sec, axis=(1, 2)) / np.linalg.norm(prim, axis=(1, 2))).max()) > preset.clean_tolerance:
                    continue
            scene.objects.append(ob)
        if preset.carry_fraction > 0:
            active = np.zeros(T, dtype=bool)
            target = preset.carry_fraction * T
            tries = 0
            while active.sum() < target and tries < 50:
                tries += 1
                L = min(int(rng.uniform(*preset.carry_bout_s) * fps), int(1.2 * target) + 1)
                t0 = int(rng.integers(min(int(preset.clean_start_s * fps), T - 1), max(int(preset.clean_start_s * fps) + 1, T - L // 2)))
                active[t0:t0 + L] = True
            if active.any():
                kind = str(rng.choice(preset.carry_catalogue))
                d = _unit(rng.standard_normal(3))
                ob = make_object(kind, np.zeros(3), d, float(rng.uniform(*preset.carry_offset)),
                                 float(rng.uniform(*preset.eta)), rng, carrier=name)
                ob.active = active
                scene.objects.append(ob)
    return scene


def _coil_error(preset: ConditionPreset, rng: np.random.Generator) -> np.ndarray:
    """Per-session sensor-coil error ``E`` (3, 3): measured ``V' = E V`` (gain and axis errors)."""
    G = np.diag(1.0 + preset.coil_gain_sigma * rng.standard_normal(3))
    mis = np.deg2rad(preset.coil_misalign_deg) * rng.standard_normal((3, 3))
    np.fill_diagonal(mis, 0.0)
    return G @ (np.eye(3) + mis)


@dataclass
class SensorStreams:
    """One EM sensor in one simulated condition, all at ``fps``, source frame (float64 numpy).

    Attributes:
        name: sensor site.
        R_true, p_true: ``(T, 3, 3)``, ``(T, 3)`` true pose relative to the source (m).
        R, p: measured (interfered) pose solved from the voltages.
        gyro: ``(T, 3)`` rad/s, angular velocity relative to the source, sensor frame (IMU).
        acc: ``(T, 3)`` m/s^2, acceleration relative to the source, source frame, gravity removed (IMU).
        valid: ``(T,)`` bool (False where the solver failed; none so far).
        pos_error: ``(T,)`` m, ``|p - p_true|``; rot_error: ``(T,)`` rad, geodesic.
        residual: ``(T,)`` relative voltage fit residual of the tracker.
        carried: ``(T,)`` bool, a carried object is in the hand (ground truth of persistent interference).
        fps: Hz.
    """

    name: str
    R_true: np.ndarray
    p_true: np.ndarray
    R: np.ndarray
    p: np.ndarray
    gyro: np.ndarray
    acc: np.ndarray
    valid: np.ndarray
    pos_error: np.ndarray
    rot_error: np.ndarray
    residual: np.ndarray
    carried: np.ndarray
    fps: float

    @property
    def num_frames(self) -> int:
        return int(self.p.shape[0])


@dataclass
class ConditionSim:
    """Output of :func:`simulate_condition`: ``sensors[name]`` -> :class:`SensorStreams`."""

    condition: ConditionPreset
    sensors: dict[str, SensorStreams]
    scene: Scene
    seed: int
    fps: float = EM_RATE
    meta: dict[str, Any] = field(default_factory=dict)

    def __getitem__(self, name: str) -> SensorStreams:
        return self.sensors[name]


def _seed(seed: int, key: str) -> np.random.Generator:
    return np.random.default_rng([int(seed) & 0x7FFFFFFF, zlib.crc32(key.encode())])


def rotation_error(R1: np.ndarray, R2: np.ndarray) -> np.ndarray:
    """Geodesic angle (rad) between ``(..., 3, 3)`` rotation arrays (via :mod:`wearpose.geometry`)."""
    return geodesic_angle(torch.from_numpy(np.ascontiguousarray(R1)), torch.from_numpy(np.ascontiguousarray(R2))).numpy()


def simulate_condition(motion_or_trajectories: Any, condition: str | ConditionPreset = "standard", *,
                       sensors: Sequence[str] = ("left_wrist", "right_wrist"), seed: int = 0, body: Any = None,
                       source: str = "head", imu_noise: ImuNoise | None = ImuNoise(), scene: Scene | None = None,
                       tracker: TrackerConfig | None = None, floor_height: float | None = None,
                       source_pose: tuple[Any, Any] | None = None) -> ConditionSim:
    """Simulate EM tracking with metal interference (module doc).

    Args:
        motion_or_trajectories: a :class:`~wearpose.motion.MotionSequence` (needs ``body``; the
            embedded body model by default) or :class:`SiteTrajectories` (already at 120 Hz).
        condition: ``"open-space"``, ``"standard"``, ``"extreme"`` or a :class:`ConditionPreset`.
        sensors: EM sensor sites. With ``source="head"`` the head cannot be one of them.
        seed: seeds the scene, the noise and the IMU.
        source: ``"head"`` (MI-Poser) or ``"world"`` (fixed source, MI-Poser User Study 2).
        imu_noise: IMU error model (``None`` = ideal IMU).
        scene: use this scene instead of drawing one.
        tracker: solver settings (default: numpy LM, the same least-squares problem as scipy's).
        floor_height: world ``y`` of the floor; default: 0 (the corpus puts the feet on y = 0).
        source_pose: ``(R (3, 3), p (3,))`` of a room-fixed source (``source="world"``); default
            as :func:`~wearpose.interference.trajectories.body_trajectories`.

    Returns:
        :class:`ConditionSim`.
    """
    preset = get_condition(condition)
    if isinstance(motion_or_trajectories, SiteTrajectories):
        traj = motion_or_trajectories
        if abs(traj.fps - EM_RATE) > 1e-6:
            raise ConfigError(f"simulate_condition: trajectories must be at {EM_RATE} Hz, got {traj.fps}")
    else:
        if body is None:
            body = BodyModel()
        traj = body_trajectories(motion_or_trajectories, body, sensors, source=source, source_pose=source_pose)
    fps = traj.fps
    if scene is None:
        scene = draw_scene(preset, traj, _seed(seed, "scene"), 0.0 if floor_height is None else floor_height)
    R_rel, p_rel = (x.numpy() for x in traj.relative())
    Rw, Pw = traj.R.numpy(), traj.p.numpy()
    sR, sp = traj.src_R.numpy(), traj.src_p.numpy()
    carriers = {n: (Rw[:, i], Pw[:, i]) for i, n in enumerate(traj.names)}
    out: dict[str, SensorStreams] = {}
    for i, name in enumerate(traj.names):
        rng = _seed(seed, f"em:{name}")
        V = measured_voltages(scene, Rw[:, i], Pw[:, i], sR, sp, carriers, noise=0.0)
        V = np.einsum("ij,tjk->tik", _coil_error(preset, rng), V)
        if preset.voltage_noise > 0:
            V = V + preset.voltage_noise * rng.standard_normal(V.shape)
        cfg = tracker or TrackerConfig(solver="numpy")
        # operating hemisphere set once at installation: the side of the source the sensor starts on
        cfg = replace(cfg, hemisphere=tuple(float(x) for x in p_rel[0, i]))
        Rm, pm, res = EMTracker(cfg).track(V)
        imu = simulate_imu(torch.from_numpy(R_rel[:, i:i + 1].copy()), torch.from_numpy(p_rel[:, i:i + 1].copy()), fps,
                           noise=imu_noise, generator=torch.Generator().manual_seed(int(_seed(seed, f"imu:{name}").integers(2 ** 62))))
        carried = np.zeros(traj.num_frames, dtype=bool)
        for ob in scene.objects:
            if ob.carrier == name:
                carried |= ob.active if ob.active is not None else True
        out[name] = SensorStreams(
            name, R_rel[:, i].copy(), p_rel[:, i].copy(), Rm, pm,
            imu["angular_velocity"][:, 0].numpy(), imu["acceleration"][:, 0].numpy(),
            np.isfinite(pm).all(axis=1), np.linalg.norm(pm - p_rel[:, i], axis=1), rotation_error(Rm, R_rel[:, i]),
            res, carried, fps)
    return ConditionSim(preset, out, scene, int(seed), fps, {"source": source, "frames": traj.num_frames})

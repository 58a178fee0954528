"""``simulate``: a motion sequence + a sensor kit + a body -> per-sensor simulated streams.

The body's sites are evaluated once per distinct sensor rate (``body.sites``, the fast path that
skins only the site patches), after resampling the motion to that rate with
:func:`wearpose.motion.resample.resample` when the motion's rate differs. Each sensor kind then
runs its simulator on its sites: EM (:mod:`.em`), IMU (:mod:`.imu`), MIMU (:mod:`.mimu`), VIO
(:mod:`.vio`).

Randomness: one ``seed`` per call. Every sensor gets its own generator seeded from
``(seed, sensor name)``, so a sensor's noise does not change when other sensors are added to or
removed from a kit. The per-sequence EM offset draw (EM-POSE supp. 2.2) uses ``(seed, "offsets")``,
a random wearer's body shape (``shape="random"`` / ``"heldout"``, :func:`random_body_shape`)
``(seed, "body-shape")`` / ``(seed, "body-shape:heldout")``.

Bodies of every size: ``shape`` (default ``None``: the motion's own ``betas``, unchanged) puts
the kit on another body shape, the motion re-fitted to it first
(:func:`wearpose.motion.refit_to_body`: joint rotations kept, root height and travel from that
body's legs, planted feet kept planted); the re-fitted motion is the ground truth
(:attr:`SimulationResult.motion`).
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass, field, replace
from typing import Any, Sequence

import torch

from wearpose.body.shapes import sample_betas
from wearpose.errors import ConfigError, ShapeError
from wearpose.motion.resample import resample
from wearpose.motion.retarget import refit_to_body
from wearpose.motion.sequence import MotionSequence
from wearpose.sensors.em import EMNoise, EMOffsets, random_subject_offsets, simulate_em
from wearpose.sensors.imu import ImuNoise, simulate_imu
from wearpose.body.skeleton import JOINT_INDEX
from wearpose.sensors.kits import SITE_SEGMENT, SensorKit, get_kit, resolve_sites
from wearpose.sensors.mimu import MimuNoise, simulate_mimu
from wearpose.sensors.vio import VioNoise, simulate_vio


@dataclass(frozen=True)
class NoiseConfig:
    """Error models per sensor kind (``None`` = ideal for that kind)."""

    em: EMNoise | None = EMNoise()
    imu: ImuNoise | None = ImuNoise()
    mimu: MimuNoise | None = MimuNoise()
    vio: VioNoise | None = VioNoise()

    @staticmethod
    def default() -> NoiseConfig:
        return NoiseConfig()

    @staticmethod
    def none() -> NoiseConfig:
        return NoiseConfig(None, None, None, None)


@dataclass
class SensorData:
    """One simulated sensor stream. ``T`` = samples at ``rate``.

    Attributes:
        name, kind, site, rate: from the kit (``site`` is the site actually used).
        timestamps: ``(T,)`` float64 seconds from the motion's first frame.
        valid: ``(T,)`` bool; False frames hold NaN (EM) or zeros (inertial ends, ``ends="mask"``).
        frame: ``"source"`` (EM: position/orientation relative to the EM source frame) or
            ``"world"`` (IMU/MIMU/VIO: orientation ``R_WS`` to the Y-up world).
        position: ``(T, 3)`` m (EM, VIO) or None.
        orientation: ``(T, 3, 3)`` sensor -> frame, or None.
        acceleration: ``(T, 3)`` free acceleration, world frame, gravity removed, m/s^2 (IMU, MIMU).
        angular_velocity: ``(T, 3)`` rad/s, sensor frame (IMU, MIMU).
        specific_force: ``(T, 3)`` raw accelerometer, sensor frame, gravity included, m/s^2.
        magnetic_field: ``(T, 3)`` tesla, sensor frame (MIMU).
        extras: ground-truth or diagnostic series (e.g. ``distance`` to the EM source,
            ``yaw_error``, ``world_position``).
    """

    name: str
    kind: str
    site: str
    rate: float
    timestamps: torch.Tensor
    valid: torch.Tensor
    frame: str
    position: torch.Tensor | None = None
    orientation: torch.Tensor | None = None
    acceleration: torch.Tensor | None = None
    angular_velocity: torch.Tensor | None = None
    specific_force: torch.Tensor | None = None
    magnetic_field: torch.Tensor | None = None
    extras: dict[str, torch.Tensor] = field(default_factory=dict)

    @property
    def num_frames(self) -> int:
        return int(self.timestamps.shape[0])


@dataclass
class SimulationResult:
    """Output of :func:`simulate`.

    Attributes:
        kit: the kit simulated (with ``rate`` overrides applied).
        sensors: sensor name -> :class:`SensorData`, kit order.
        seed: the seed used.
        noise: the :class:`NoiseConfig` used.
        em_offsets: the EM offsets drawn for this sequence (kit order of the EM sensors), or None.
        em_source: ground-truth source pose per EM rate: ``{rate: {"position": (T, 3),
            "orientation": (T, 3, 3)}}`` (world), for calibration and evaluation.
        site_substitutions: sensor -> "wanted -> used" for sites the body lacks.
        meta: body asset id, motion fps, frames (and the wearer's ``betas`` when ``shape`` was given).
        motion: the motion that was simulated when ``shape`` re-fitted it to another body (the
            ground truth to store with the streams); ``None`` when the input motion was used.
    """

    kit: SensorKit
    sensors: dict[str, SensorData]
    seed: int
    noise: NoiseConfig
    em_offsets: EMOffsets | None = None
    em_source: dict[float, dict[str, torch.Tensor]] = field(default_factory=dict)
    site_substitutions: dict[str, str] = field(default_factory=dict)
    meta: dict[str, Any] = field(default_factory=dict)
    motion: MotionSequence | None = None

    def __getitem__(self, name: str) -> SensorData:
        return self.sensors[name]

    @property
    def num_sensor_frames(self) -> int:
        """Total sensor-frames simulated (sum over sensors of their sample counts)."""
        return sum(s.num_frames for s in self.sensors.values())


def _generator(seed: int, key: str) -> torch.Generator:
    g = torch.Generator()
    g.manual_seed((int(seed) * 1_000_003 + zlib.crc32(key.encode())) % (2 ** 63 - 1))
    return g


#: ``shape`` values that draw a wearer, and the generator stream each draws from. ``"random"``
#: is for training data; ``"heldout"`` for evaluation: a stream no training path draws from, on
#: top of the evaluation seed namespaces the estimators already use (``clip_seed(..., "eval")``).
SHAPE_STREAMS: dict[str, str] = {"random": "body-shape", "heldout": "body-shape:heldout"}


def random_body_shape(seed: int, num_betas: int = 10, draw: str = "random") -> torch.Tensor:
    """The body shape ``(num_betas,)`` that ``simulate(..., seed=seed, shape=draw)`` puts the kit
    on: :func:`wearpose.body.shapes.sample_betas` (the asset's adult distribution) from the
    ``(seed, SHAPE_STREAMS[draw])`` stream. The seed is the clip's simulation seed, so a clip's
    wearer is reproducible and the clip's seed namespace also separates training from
    evaluation wearers."""
    if draw not in SHAPE_STREAMS:
        raise ConfigError(f"body shape draw {draw!r}; expected one of {', '.join(SHAPE_STREAMS)}")
    return sample_betas(_generator(seed, SHAPE_STREAMS[draw]), num_betas)


def _shaped(motion: MotionSequence, body: Any, shape: str | torch.Tensor, seed: int) -> MotionSequence:
    if isinstance(shape, str):
        if shape not in SHAPE_STREAMS:
            raise ConfigError(f"simulate: shape must be 'random', 'heldout', a (num_betas,) tensor or None, got {shape!r}")
        betas = random_body_shape(seed, int(motion.betas.shape[-1]), shape)
    else:
        betas = torch.as_tensor(shape, dtype=torch.float32)
        if tuple(betas.shape) != tuple(motion.betas.shape):
            raise ShapeError(f"simulate: shape expected {tuple(motion.betas.shape)} betas like the motion's, "
                             f"got {tuple(betas.shape)}")
    return refit_to_body(motion, body, betas)


def _noise_config(noise: str | NoiseConfig) -> NoiseConfig:
    if isinstance(noise, NoiseConfig):
        return noise
    if noise == "default":
        return NoiseConfig.default()
    if noise == "none":
        return NoiseConfig.none()
    if noise == "ximu3":  # inertial terms fitted to a real x-IMU3 log (ImuNoise.ximu3); EM and VIO default
        return NoiseConfig(imu=ImuNoise.ximu3(), mimu=replace(MimuNoise(), imu=ImuNoise.ximu3()))
    raise ConfigError(f"simulate: noise must be 'default', 'none', 'ximu3' or a NoiseConfig, got {noise!r}")


def simulate(motion: MotionSequence, kit: str | SensorKit, body: Any, *, seed: int = 0,
             noise: str | NoiseConfig = "default", offsets: EMOffsets | Sequence[EMOffsets] | str | None = None,
             rate: float | None = None, imu_smooth_n: int | None = None, acc_ends: str = "one_sided",
             em_fill: str = "nan", imu_orientation: str = "site", mimu_fusion: str | None = None,
             shape: str | torch.Tensor | None = None) -> SimulationResult:
    """Simulate a sensor kit worn by a body performing ``motion``.

    Args:
        motion: the motion (pose, betas, trans at ``motion.fps``).
        kit: kit name (:func:`wearpose.sensors.list_kits`) or a :class:`SensorKit`.
        body: a :class:`wearpose.body.BodyModel` whose sites the kit names.
        seed: seeds every random process of this call.
        noise: ``"default"`` (the documented error models), ``"none"`` (ideal sensors, no
            dropped frames) or a :class:`NoiseConfig`.
        offsets: EM sensor offsets ``O_p`` (kit order of the EM sensors): an
            :class:`EMOffsets` (its translation covariance, if any, is drawn from once for this
            sequence, EM-POSE supp. 2.2), ``"random"`` for a synthetic subject
            (:func:`wearpose.sensors.em.random_subject_offsets`), or ``None`` for identity (the
            sensor is the skin frame of EM-POSE Eq. 3). A sequence of :class:`EMOffsets` (one
            per calibrated participant) picks one at random for this sequence, as EM-POSE
            trains ("for each AMASS sequence ... we randomly decide on a participant p whose
            offsets O_p should be applied", Sec. 5.3); the index is in ``meta["offsets_index"]``.
        rate: override every sensor's rate (Hz); default: the kit's rates.
        imu_smooth_n: acceleration stencil half-width in frames at the sensor rate; default
            ``None`` keeps TransPose/PIP's window (4 frames at 60 Hz = 1/15 s) at any rate,
            ``round(4 * rate / 60)``; 1 disables smoothing.
        acc_ends: end handling of the acceleration (:func:`wearpose.sensors.imu.synthetic_acceleration`).
        em_fill: value of dropped EM frames, ``"nan"`` or ``"zero"``.
        imu_orientation: orientation of IMU/MIMU sensors: ``"site"`` (default: the skin frame
            of the site, EM-POSE Eq. 3 -- a physical sensor with a sensor-to-segment offset) or
            ``"segment"`` (the global rotation of the bone the site is on,
            :data:`wearpose.sensors.kits.SITE_SEGMENT`: what TransPose/PIP synthesise and
            what BiRAE assumes after calibration). Either way the position (hence the
            acceleration) is the site vertex, and ``extras["segment_orientation"]`` holds the
            bone's ground-truth rotation.
        mimu_fusion: ``None`` (analytic BiRAE-style error model) or ``"madgwick"`` /
            ``"madgwick_imu"`` (a real AHRS filter, optional package ``ahrs``;
            :func:`wearpose.sensors.mimu.simulate_mimu`).
        shape: the wearer's body shape: ``None`` (default) the motion's ``betas``; ``"random"``
            (training data) or ``"heldout"`` (evaluation) one drawn from ``seed``
            (:func:`random_body_shape`, :data:`SHAPE_STREAMS`); or ``(num_betas,)`` betas. Any
            other than ``None`` re-fits the motion to that body first (module doc) and returns
            it as :attr:`SimulationResult.motion`.

    Returns:
        :class:`SimulationResult`.
    """
    if not isinstance(motion, MotionSequence):
        raise ShapeError(f"simulate: motion must be a MotionSequence, got {type(motion).__name__}")
    kit = get_kit(kit)
    if rate is not None:
        kit = kit.with_rate(rate)
    shaped = _shaped(motion, body, shape, seed) if shape is not None else None
    motion = shaped if shaped is not None else motion
    cfg = _noise_config(noise)
    if imu_orientation not in ("site", "segment"):
        raise ConfigError(f"simulate: imu_orientation must be 'site' or 'segment', got {imu_orientation!r}")
    sites, subs = resolve_sites(kit, body.site_names, getattr(body, "asset_id", "?"))

    em_specs = kit.of_kind("em6dof")
    em_off: EMOffsets | None = None
    offsets_index: int | None = None
    if em_specs:
        if offsets is None:
            em_off = EMOffsets.identity(len(em_specs))
        elif isinstance(offsets, str):
            if offsets != "random":
                raise ConfigError(f"simulate: offsets must be an EMOffsets, 'random' or None, got {offsets!r}")
            em_off = random_subject_offsets(len(em_specs), _generator(seed, "subject")).draw(_generator(seed, "offsets"))
        else:
            if not isinstance(offsets, EMOffsets):
                pool = list(offsets)
                if not pool or not all(isinstance(o, EMOffsets) for o in pool):
                    raise ConfigError("simulate: offsets must be an EMOffsets, a non-empty sequence of them, 'random' or None")
                offsets_index = int(torch.randint(len(pool), (1,), generator=_generator(seed, "participant")))
                offsets = pool[offsets_index]
            if offsets.num_sensors != len(em_specs):
                raise ShapeError(f"simulate: {offsets.num_sensors} EM offsets for the {len(em_specs)} EM sensors of kit {kit.name!r}")
            em_off = offsets.draw(_generator(seed, "offsets"))
    em_index = {s.name: i for i, s in enumerate(em_specs)}

    out: dict[str, SensorData] = {}
    em_source: dict[float, dict[str, torch.Tensor]] = {}
    for r in kit.rates:
        group = [s for s in kit.sensors if float(s.rate) == r]
        m = motion if abs(motion.fps - r) < 1e-9 else resample(motion, r)
        T = m.num_frames
        ts = torch.arange(T, dtype=torch.float64) / r
        smooth_n = imu_smooth_n if imu_smooth_n is not None else max(1, int(round(4 * r / 60.0)))
        names = list(dict.fromkeys([sites[s.name] for s in group]
                                   + ([sites["<em_source>"]] if any(s.kind == "em6dof" for s in group) else [])))
        so = body.sites(m.pose, m.betas, m.trans, names)
        col = {n: i for i, n in enumerate(names)}
        P, R = so.positions, so.rotations  # (T, K, 3), (T, K, 3, 3)

        def take(specs: list) -> tuple[torch.Tensor, torch.Tensor]:
            idx = [col[sites[s.name]] for s in specs]
            return R[:, idx], P[:, idx]

        for kind in ("em6dof", "imu", "mimu", "vio"):
            specs = [s for s in group if s.kind == kind]
            if not specs:
                continue
            Rk, Pk = take(specs)
            if kind == "em6dof":
                src = col[sites["<em_source>"]]
                sub = EMOffsets(em_off.R[[em_index[s.name] for s in specs]], em_off.t[[em_index[s.name] for s in specs]])
                res_list = []
                # One generator per sensor: simulate sensor by sensor (cheap; EM work is tiny).
                for j, s in enumerate(specs):
                    one = EMOffsets(sub.R[j:j + 1], sub.t[j:j + 1])
                    res_list.append(simulate_em(Rk[:, j:j + 1], Pk[:, j:j + 1], R[:, src], P[:, src], r, offsets=one,
                                                noise=cfg.em, fill=em_fill, generator=_generator(seed, s.name)))
                em_source[r] = {"position": P[:, src].clone(), "orientation": R[:, src].clone()}
                for s, res in zip(specs, res_list):
                    out[s.name] = SensorData(s.name, kind, sites[s.name], r, ts, res["valid"][:, 0], "source",
                                             position=res["position"][:, 0], orientation=res["orientation"][:, 0],
                                             extras={"distance": res["distance"][:, 0],
                                                     "world_position": res["world_position"][:, 0],
                                                     "world_orientation": res["world_orientation"][:, 0]})
            else:
                for j, s in enumerate(specs):
                    g = _generator(seed, s.name)
                    Rj, Pj = Rk[:, j:j + 1], Pk[:, j:j + 1]
                    seg = so.global_rot[:, JOINT_INDEX[SITE_SEGMENT[sites[s.name]]]] if sites[s.name] in SITE_SEGMENT else None
                    if kind in ("imu", "mimu") and imu_orientation == "segment":
                        if seg is None:
                            raise ConfigError(f"simulate: no segment known for site {sites[s.name]!r} (sensor {s.name!r}); "
                                              f"known: {sorted(SITE_SEGMENT)}")
                        Rj = seg[:, None]
                    gt = {} if seg is None else {"segment_orientation": seg}
                    if kind == "imu":
                        res = simulate_imu(Rj, Pj, r, noise=cfg.imu, smooth_n=smooth_n, ends=acc_ends, generator=g)
                        out[s.name] = SensorData(s.name, kind, sites[s.name], r, ts, res["valid"], "world",
                                                 orientation=res["orientation"][:, 0], acceleration=res["acceleration"][:, 0],
                                                 angular_velocity=res["angular_velocity"][:, 0],
                                                 specific_force=res["specific_force"][:, 0], extras=dict(gt))
                    elif kind == "mimu":
                        res = simulate_mimu(Rj, Pj, r, noise=cfg.mimu, smooth_n=smooth_n, ends=acc_ends, generator=g,
                                            fusion=mimu_fusion)
                        out[s.name] = SensorData(s.name, kind, sites[s.name], r, ts, res["valid"], "world",
                                                 orientation=res["orientation"][:, 0], acceleration=res["acceleration"][:, 0],
                                                 angular_velocity=res["angular_velocity"][:, 0],
                                                 specific_force=res["specific_force"][:, 0],
                                                 magnetic_field=res["magnetic_field"][:, 0],
                                                 extras={"yaw_error": res["yaw_error"][:, 0], "disturbance": res["disturbance"][:, 0],
                                                         **gt})
                    else:
                        res = simulate_vio(Rj, Pj, r, noise=cfg.vio, generator=g)
                        out[s.name] = SensorData(s.name, kind, sites[s.name], r, ts, res["valid"], "world",
                                                 position=res["position"][:, 0], orientation=res["orientation"][:, 0],
                                                 extras={"yaw_drift": res["yaw_drift"][:, 0],
                                                         "position_drift": res["position_drift"][:, 0]})
    ordered = {s.name: out[s.name] for s in kit.sensors}
    return SimulationResult(kit, ordered, int(seed), cfg, em_off, em_source, subs,
                            {"body_asset": getattr(body, "asset_id", "?"), "motion_fps": motion.fps,
                             "motion_frames": motion.num_frames, "offsets_index": offsets_index,
                             **({"betas": [float(x) for x in motion.betas]} if shaped is not None else {})},
                            motion=shaped)

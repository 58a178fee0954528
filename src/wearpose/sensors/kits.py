"""Sensor kits: named layouts of body-worn sensors (which kind, on which skin site, at what rate).

A kit is pure data: it names *sites* of the body asset (``BodyModel.site_names``), never vertex
ids, so the same kit works on the embedded asset and on a user's SMPL file as long as both
define the sites. Sites on the embedded asset ``wearpose_anny_v1``: head, sternum, back_upper,
pelvis, {left,right}_{upper_arm, forearm, wrist, thigh, shin, foot, shoulder}.

Registered kits (sources):

- ``em12`` / ``em6`` -- EM-POSE (Kaufmann et al., ICCV 2021). 12 wireless EM sensors at 120 Hz,
  source on the lower back (Sec. 4.1). The 12 sensors and their order follow the public code
  (``facebookresearch/em-pose``, ``empose/helpers/configuration.py``, ``S_ORDER``): back, head,
  right lower arm ("r_wrist"), right upper arm, right shoulder, right upper leg, right lower leg,
  then the same on the left. The 6-sensor subset "only keeps the sensors at the wrists, lower
  legs, head, and back" (Sec. 6.2; ``S_CONFIG_6 = [0, 1, 2, 6, 7, 11]``).
  The "back" sensor sits between the source (root) and the head in the code's tracker skeleton
  (root -> back -> head/shoulders), so it maps to ``back_upper``; the source (lower back) maps
  to ``pelvis``.
  The shoulder sensors sit on top of the shoulder, over the acromion (sites
  ``left_shoulder``/``right_shoulder``): the paper counts them with the head among the "static or
  slow moving sensors" (Sec. 6.1) and the code's tracker skeleton chains back -> shoulder ->
  upper arm, i.e. a sensor on the shoulder girdle between the back and the upper-arm sensor,
  not a second upper-arm sensor. Their segment is the collar (:data:`SITE_SEGMENT`).
  A kit may still name fallback sites for assets that lack a site (``SensorSpec.fallback_sites``,
  :func:`resolve_sites`); no built-in kit needs one on the embedded asset.
- ``imu6`` -- DIP / TransPose / PIP: left/right forearm, left/right lower leg (shin), head,
  pelvis (PIP Sec. 3: "mounted on the left/right forearms, left/right lower legs, head, and
  pelvis"; TransPose ``vi_mask = [1961, 5424, 1176, 4662, 411, 3021]``), 60 Hz.
- ``mimu6`` -- BiRAE (Sec. IV-C "Sensor placement"): "Six MIMU sensors are placed near left
  wrist, right wrist, left lower leg, right lower leg, lower spine and head. The sensor at lower
  spine is treated as reference or root sensor." Synthetic data at 60 Hz (Sec. IV-A).
- ``miposer`` -- MI-Poser (Sec. 3-4): AR-glasses VIO (60 Hz) on the head, EMF source in the
  glasses (head), two wrist EMF receivers (120 Hz) each with a co-located IMU streaming
  synchronously at 120 Hz (Sec. 6.1.1).
- ``miposer1`` -- the single-wrist "smartwatch" variant (Sec. 5.2.1), left wrist.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Iterable, Mapping

from wearpose.errors import ConfigError, WearposeError

#: Sensor kinds understood by the simulators.
SENSOR_KINDS: tuple[str, ...] = ("em6dof", "imu", "mimu", "vio")


#: SMPL joint whose global rotation is the *segment* orientation of a site: the bone the sensor
#: is strapped to. Matches TransPose/PIP's ``ji_mask = [18, 19, 4, 5, 15, 0]`` for the forearm,
#: shin, head and pelvis sites (their IMU orientation is the joint's global rotation) and
#: BiRAE's "sensor-to-segment alignment is identity"; a wrist-watch site rides on the forearm.
SITE_SEGMENT: dict[str, str] = {
    "head": "head", "sternum": "spine3", "back_upper": "spine3", "pelvis": "pelvis",
    **{f"{lr}_{site}": f"{lr}_{joint}" for lr in ("left", "right") for site, joint in (
        ("shoulder", "collar"), ("upper_arm", "shoulder"), ("forearm", "elbow"), ("wrist", "elbow"),
        ("thigh", "hip"), ("shin", "knee"), ("foot", "ankle"))},
}


class KitError(ConfigError):
    """Unknown kit, malformed kit, or a kit that does not fit a body asset."""


@dataclass(frozen=True)
class SensorSpec:
    """One sensor of a kit.

    Attributes:
        name: unique name within the kit (e.g. ``"left_wrist"``).
        kind: one of :data:`SENSOR_KINDS`.
        site: body-asset site the sensor is strapped to.
        rate: sample rate, Hz.
        fallback_sites: sites to use, in order, when the asset lacks ``site`` (a documented
            approximation; the substitution is reported, never silent).
    """

    name: str
    kind: str
    site: str
    rate: float
    fallback_sites: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.kind not in SENSOR_KINDS:
            raise KitError(f"sensor {self.name!r}: kind {self.kind!r} is not one of {SENSOR_KINDS}")
        if not (self.rate > 0):
            raise KitError(f"sensor {self.name!r}: rate must be > 0 Hz, got {self.rate!r}")


@dataclass(frozen=True)
class SensorKit:
    """A named sensor layout.

    Attributes:
        name: registry name.
        sensors: the sensors, in the order estimators expect them.
        em_source_site: site carrying the EM field source (``None`` without EM sensors). EM
            measurements are expressed in this site's frame (DESIGN: EM canonical form).
        description: one line with the source paper.
    """

    name: str
    sensors: tuple[SensorSpec, ...]
    em_source_site: str | None = None
    description: str = ""
    meta: dict = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        names = [s.name for s in self.sensors]
        if len(set(names)) != len(names):
            raise KitError(f"kit {self.name!r}: duplicate sensor names {names}")
        if any(s.kind == "em6dof" for s in self.sensors) and self.em_source_site is None:
            raise KitError(f"kit {self.name!r} has EM sensors but no em_source_site")

    @property
    def sensor_names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.sensors)

    @property
    def rates(self) -> tuple[float, ...]:
        """Distinct sensor rates (Hz), sorted."""
        return tuple(sorted({float(s.rate) for s in self.sensors}))

    def sensor(self, name: str) -> SensorSpec:
        for s in self.sensors:
            if s.name == name:
                return s
        raise KitError(f"kit {self.name!r} has no sensor {name!r}; sensors: {list(self.sensor_names)}")

    def of_kind(self, kind: str) -> tuple[SensorSpec, ...]:
        return tuple(s for s in self.sensors if s.kind == kind)

    def with_rate(self, rate: float) -> SensorKit:
        """The same kit with every sensor at ``rate`` Hz."""
        return SensorKit(self.name, tuple(SensorSpec(s.name, s.kind, s.site, float(rate), s.fallback_sites)
                                          for s in self.sensors), self.em_source_site, self.description, dict(self.meta))


_REGISTRY: dict[str, SensorKit] = {}


def register_kit(kit: SensorKit, *, overwrite: bool = False) -> SensorKit:
    """Add ``kit`` to the registry (``overwrite`` to replace an existing name)."""
    if kit.name in _REGISTRY and not overwrite:
        raise KitError(f"kit {kit.name!r} is already registered")
    _REGISTRY[kit.name] = kit
    return kit


def list_kits() -> tuple[str, ...]:
    """Names of the registered kits, sorted."""
    return tuple(sorted(_REGISTRY))


def get_kit(name: str | SensorKit) -> SensorKit:
    """Registered kit by name (a :class:`SensorKit` is returned unchanged)."""
    if isinstance(name, SensorKit):
        return name
    try:
        return _REGISTRY[name]
    except (KeyError, TypeError):
        raise KitError(f"unknown sensor kit {name!r}; available kits: {', '.join(list_kits())}") from None


def resolve_sites(kit: SensorKit, site_names: Iterable[str], asset_id: str = "?") -> tuple[dict[str, str], dict[str, str]]:
    """Map each sensor (and the EM source) to a site present on a body asset.

    Args:
        kit: the kit.
        site_names: the asset's site names (``BodyModel.site_names``).
        asset_id: for messages.

    Returns:
        ``(sites, substitutions)``: sensor name (and ``"<em_source>"``) -> site used, and
        sensor name -> ``"wanted -> used"`` for every fallback taken.

    Raises:
        KitError: a site (and all its fallbacks) is missing; the message names the site, the
            sensor, the kit, the asset and the sites the asset has.
    """
    have = set(site_names)
    sites: dict[str, str] = {}
    subs: dict[str, str] = {}
    missing: list[str] = []
    for s in kit.sensors:
        for cand in (s.site, *s.fallback_sites):
            if cand in have:
                sites[s.name] = cand
                if cand != s.site:
                    subs[s.name] = f"{s.site} -> {cand}"
                break
        else:
            missing.append(f"site {s.site!r} (sensor {s.name!r})")
    if kit.em_source_site is not None:
        if kit.em_source_site in have:
            sites["<em_source>"] = kit.em_source_site
        else:
            missing.append(f"site {kit.em_source_site!r} (EM source)")
    if missing:
        raise KitError(f"kit {kit.name!r} does not fit body asset {asset_id!r}: missing {', '.join(missing)}; "
                       f"the asset has sites {sorted(have)}")
    if subs:
        warnings.warn(f"kit {kit.name!r} on body asset {asset_id!r}: approximate site substitutions {subs}",
                      stacklevel=2)
    return sites, subs


def _lr(prefix: str) -> tuple[str, str]:
    return f"left_{prefix}", f"right_{prefix}"


def _sensors(kind: str, rate: float, sites: Mapping[str, str]) -> tuple[SensorSpec, ...]:
    """Sensors of one ``kind`` sampled at ``rate`` Hz: sensor name -> body site, in kit order."""
    return tuple(SensorSpec(name, kind, site, rate) for name, site in sites.items())


def _builtin() -> None:
    # EM-POSE, S_ORDER of the public code (back, head, then right arm/leg, then left).
    def em_side(side: str) -> tuple[SensorSpec, ...]:
        return _sensors("em6dof", 120.0, {f"{side}_{name}": f"{side}_{site}" for name, site in (
            ("lower_arm", "wrist"), ("upper_arm", "upper_arm"), ("shoulder", "shoulder"), ("upper_leg", "thigh"),
            ("lower_leg", "shin"))})
    em12 = (*_sensors("em6dof", 120.0, {"back": "back_upper", "head": "head"}), *em_side("right"), *em_side("left"))
    register_kit(SensorKit("em12", em12, "pelvis", "EM-POSE 12 EM sensors, source on the lower back (ICCV 2021)"))
    keep6 = [0, 1, 2, 6, 7, 11]  # S_CONFIG_6 of the EM-POSE code
    register_kit(SensorKit("em6", tuple(em12[i] for i in keep6), "pelvis",
                           "EM-POSE 6 EM sensors: back, head, wrists (lower arms), lower legs"))

    lf, rf = _lr("forearm")
    ls, rs = _lr("shin")
    register_kit(SensorKit("imu6", _sensors("imu", 60.0, {
        "left_forearm": lf, "right_forearm": rf, "left_lower_leg": ls, "right_lower_leg": rs, "head": "head",
        "pelvis": "pelvis"}), None, "DIP/TransPose/PIP 6 IMUs (order of TransPose vi_mask), 60 Hz"))

    lw, rw = _lr("wrist")
    register_kit(SensorKit("mimu6", _sensors("mimu", 60.0, {
        "left_wrist": lw, "right_wrist": rw, "left_lower_leg": ls, "right_lower_leg": rs, "head": "head",
        "root": "pelvis"}), None, "BiRAE 6 MIMUs: wrists, lower legs, head, lower spine (root), 60 Hz"))

    register_kit(SensorKit("miposer", (
        SensorSpec("head_vio", "vio", "head", 60.0),
        SensorSpec("left_wrist_em", "em6dof", lw, 120.0), SensorSpec("right_wrist_em", "em6dof", rw, 120.0),
        SensorSpec("left_wrist_imu", "imu", lw, 120.0), SensorSpec("right_wrist_imu", "imu", rw, 120.0)),
        "head", "MI-Poser: AR-glasses VIO + EMF source on the head, 2 wrist EMF receivers with co-located IMUs"))
    register_kit(SensorKit("miposer1", (
        SensorSpec("head_vio", "vio", "head", 60.0),
        SensorSpec("left_wrist_em", "em6dof", lw, 120.0), SensorSpec("left_wrist_imu", "imu", lw, 120.0)),
        "head", "MI-Poser single-wrist (smartwatch) variant"))


_builtin()

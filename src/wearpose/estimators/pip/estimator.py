"""``PipEstimator``: PIP (kinematics RNN chain + optional physics optimizer) behind the
:class:`~wearpose.estimators.Estimator` protocol.

Input: kit ``imu6`` (left/right forearm, left/right lower leg, head, pelvis) at 60 Hz, in
canonical form (orientation ``R_WS``, free acceleration in the world frame). The network needs
*bone* orientations in wearpose's world (the subject faced +Z at calibration):

- a recording with ``meta["orientation_frame"] == "segment"`` is used as is (simulated with
  ``imu_orientation="segment"``, or already passed through
  :func:`wearpose.calibration.apply_calibration`);
- a recording carrying a ``tpose``/``ipose`` calibration in ``meta["calibration"]`` is
  calibrated here (:func:`~wearpose.calibration.apply_calibration`);
- otherwise the estimator runs PIP's T-pose calibration itself on the first
  ``calibration_window`` seconds (the wearer must stand in a T-pose then; PIP Sec. 3.1), or,
  with ``calibration_window=None``, uses the orientations as bone orientations with a warning.

Masked input: a dropped sample is held at the sensor's last valid value; frames with any
dropped sensor are ``valid = False``.

Initial state (Sec. 3.1.2, "we assume the initial pose of the subject is known, which can be
obtained from the calibration step"): :meth:`set_initial_state` (pose, velocities,
translation); default a T-pose at rest at the origin. ``learned_init`` off (or a model trained
without I_PL / I_VA) starts every LSTM from zeros.

Options (the ablations of Table 2): ``physics`` (False: translation by integrating the
estimated root velocity, no torques/forces), ``dual_pd`` (False: single PD controller).

Output: ``extras["frame"] = "world"``; root orientation = the pelvis IMU's; ``trans`` the
root translation; ``extras``: ``contacts`` ``(T, 2)`` probabilities, ``joint_vel`` ``(T, 24, 3)``
world m/s, and with physics ``torques`` ``(T, 24, 3)`` N m, ``grf`` ``(T, 2, 3)`` N,
``contact_flags``, ``qp_ms``, ``penetration_m``, ``kin_ms``.
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import torch

from wearpose.body import PARENTS
from wearpose.body.kinematics import global_to_local
from wearpose.errors import ShapeError
from wearpose.estimators.base import Estimator, PoseFrame, PoseTrack, SensorFrame
from wearpose.estimators.checkpoint import Checkpoint, NetworkCheckpointing, load_checkpoint
from wearpose.estimators.inputs import InputSpec, OnlineInput, prepare
from wearpose.estimators.pip.config import PipConfig
from wearpose.estimators.pip.data import EDGE_FRAMES, LEAF_JOINTS, imu_features
from wearpose.estimators.pip.model import NumpyStepper, PipNet
from wearpose.estimators.pip.sitting import SIT_HOLD_S
from wearpose.estimators.trainmix import mix_clause
from wearpose.estimators.pip.train import train_pip
from wearpose.estimators.registry import register_estimator
from wearpose.geometry import rot6d_to_matrix
from wearpose.estimators.seeding import init_seed, seeded


def physics_available() -> bool:
    """True when :mod:`wearpose.physics` provides the optimizer PIP drives."""
    try:
        # start-up: wearpose.physics adds ~240 ms to importing this module
        import wearpose.physics as ph
    except ImportError:
        return False
    return all(hasattr(ph, n) for n in ("PhysicsCharacter", "PhysicsConfig", "PhysicsOptimizer"))


def _span(r: tuple[float, float]) -> str:
    """``(low, high)`` as ``"low-high"``."""
    return f"{r[0]:g}-{r[1]:g}"


@register_estimator("pip")
class PipEstimator(NetworkCheckpointing, Estimator):
    """PIP (see module doc).

    Args:
        config: :class:`PipConfig` (default: the ``cpu`` preset).
        body: :class:`~wearpose.body.BodyModel` (default: the embedded asset).
        physics: run the physics optimizer (needs :mod:`wearpose.physics`).
        dual_pd: dual PD controller (False: single PD, Table 2 ablation).
        learned_init: use I_PL / I_VA at the start (only if the model has them).
        betas: ``(10,)`` subject shape (default zeros; the recording's ``subject["betas"]`` wins).
        calibration_window: ``(start_s, stop_s)`` of a T-pose for the built-in calibration of
            uncalibrated recordings, or None.
    """

    name = "pip"
    causal = True
    lookahead = 0

    def __init__(self, config: PipConfig | None = None, body: Any = None, *, physics: bool = True, dual_pd: bool = True,
                 learned_init: bool = True, betas: Any = None, calibration_window: tuple[float, float] | None = (0.0, 1.0),
                 device: str | torch.device = "cpu") -> None:
        self.init_state(config or PipConfig.preset("cpu"), body, device)
        with seeded(init_seed(self.config.seed)):  # initial weights: a function of the seed (issue 24)
            self.model = PipNet(self.config).to(self.device)
        self.physics = bool(physics)
        self.dual_pd = bool(dual_pd)
        self.learned_init = bool(learned_init)
        self.calibration_window = calibration_window
        self.betas = torch.zeros(10) if betas is None else torch.as_tensor(betas, dtype=torch.float32).reshape(10)
        self._init: dict[str, torch.Tensor] | None = None
        self._optimizer: Any = None
        #: extra :class:`~wearpose.physics.PhysicsConfig` fields for the optimizer (experiments)
        self.physics_options: dict[str, Any] = {}
        self._char: tuple[tuple[float, ...], Any] | None = None
        #: online steps run the LSTMs in numpy (:class:`NumpyStepper`; same arithmetic, ~10x less
        #: per-frame overhead than torch at batch 1); False = torch
        self.fast_step = True
        self._stepper: tuple[Any, NumpyStepper] | None = None

        self._parents_np = np.array([max(p, 0) for p in PARENTS])
        self.reset()

    # ------------------------------------------------------------------ checkpoints
    # to / checkpoint / save: NetworkCheckpointing
    @classmethod
    def load(cls, path: str | Path, *, kit: str | None = None, body: Any = None,
             map_location: str | torch.device = "cpu", **options: Any) -> PipEstimator:
        """Read a checkpoint; ``options`` are the constructor's (``physics``, ``dual_pd``,
        ``learned_init``, ``betas``, ``calibration_window``)."""
        return cls.from_checkpoint(load_checkpoint(path, map_location), kit=kit, body=body, device=map_location,
                                   path=path, **options)

    @classmethod
    def from_checkpoint(cls, ckpt: Checkpoint, *, kit: str | None = None, body: Any = None,
                        device: str | torch.device = "cpu", path: str | Path = "<checkpoint>",
                        **options: Any) -> PipEstimator:
        """The estimator of a read checkpoint (:meth:`Estimator.from_checkpoint`); ``options`` as :meth:`load`."""
        body = cls.check_checkpoint(ckpt, kit=kit, body=body, path=path)
        return cls(PipConfig.from_dict(ckpt.config), body=body, device=device, **options).restore(ckpt)

    def fit(self, *args: Any, **kwargs: Any) -> Any:
        """Train (see :func:`wearpose.estimators.pip.train.train_pip`)."""
        return train_pip(self, *args, **kwargs)

    @classmethod
    def training_data_description(cls, config: Mapping[str, Any]) -> str | None:
        """The card sentence (:meth:`Estimator.training_data_description`) of
        :func:`wearpose.estimators.pip.data.build_split` on the train split and the training
        windows: corpus clips, then the augmented copies and synthetic sitting clips the config
        asks for (no clip counts of the corpus: the card has those)."""
        cfg = PipConfig.from_dict(dict(config))
        noise = {"default": "default IMU noise", "none": "no IMU noise"}[cfg.train_noise]
        text = (f"virtual IMUs, kit {cfg.kit} (wearpose.sensors.simulate, imu_orientation='segment' = bone orientations "
                f"as after a T-pose calibration, TransPose-style smoothed free accelerations, {noise}) at {cfg.rate:g} Hz, "
                f"{EDGE_FRAMES} frames cut at each clip end; targets: leaf/all joint positions, root-relative rotations, "
                f"Eq. 14 joint velocities, foot contacts")
        if cfg.max_train_clips > 0:
            text += f"; only {cfg.max_train_clips} train clips, spread evenly over the sorted split"
        text += mix_clause(cfg)
        if cfg.sitting_clips > 0:
            held = (f"balanced standing/seated holds of {_span(SIT_HOLD_S)} s"
                    if tuple(cfg.sitting_stand_s) == SIT_HOLD_S else
                    f"standing holds of {_span(cfg.sitting_stand_s)} s and seated holds of {_span(SIT_HOLD_S)} s")
            if cfg.sitting_transitions == "lean":
                held += ", sitting down and standing up with trunk lean and the knees forward"
            if cfg.sitting_hanging_arms > 0.0:
                held += f", {cfg.sitting_hanging_arms:.0%} of them with the arms hanging nearly straight"
            text += (f"; and {cfg.sitting_clips} synthetic sitting clips with {held} "
                     f"(wearpose.estimators.pip.sitting; generated here, no licence restriction)")
        text += f"; training windows of {cfg.seq_len} frames every {cfg.window_stride}"
        if cfg.min_window > 0:
            text += (f", a clip of {cfg.min_window} to {cfg.seq_len - 1} frames as one padded window and a long "
                     f"clip's tail the stride leaves out as a window of its own")
        if cfg.sitting_clips > 0 and cfg.sitting_window > 0:
            text += (f"; the synthetic sitting clips in windows of {cfg.sitting_window} frames every "
                     f"{cfg.sitting_window // 2} instead")
        return text

    # ------------------------------------------------------------------ initial state
    @torch.no_grad()
    def set_initial_state(self, pose: torch.Tensor | None = None, joint_vel: torch.Tensor | None = None,
                          trans: torch.Tensor | None = None, betas: torch.Tensor | None = None) -> None:
        """The subject's known state at the first frame (Sec. 3.1.2).

        Args:
            pose: ``(24, 3, 3)`` local rotations (default: T-pose facing +Z).
            joint_vel: ``(24, 3)`` joint velocities, root frame, m/s (PIP Eq. 14; default 0).
            trans: ``(3,)`` root translation, m (default 0).
            betas: ``(10,)`` shape (default: the estimator's).
        """
        if betas is not None:
            self.betas = torch.as_tensor(betas, dtype=torch.float32).reshape(10)
        pose = torch.eye(3).repeat(24, 1, 1) if pose is None else torch.as_tensor(pose, dtype=torch.float32)
        if pose.shape != (24, 3, 3):
            raise ShapeError(f"set_initial_state: pose must be (24, 3, 3), got {tuple(pose.shape)}")
        trans = torch.zeros(3) if trans is None else torch.as_tensor(trans, dtype=torch.float32).reshape(3)
        j = self.body(pose[None].to(self.device), self.betas[None].to(self.device), trans[None].to(self.device),
                      return_vertices=False).joints[0].cpu()
        rel = pose[0].T @ (j - j[:1]).T
        leaf = rel.T[list(LEAF_JOINTS)].reshape(15)
        vel = torch.zeros(72) if joint_vel is None else torch.as_tensor(joint_vel, dtype=torch.float32).reshape(72)
        self._init = {"pose": pose, "trans": trans, "leaf": leaf, "vel": vel / self.config.vel_scale}
        self.reset()

    def _initial(self) -> dict[str, torch.Tensor]:
        if self._init is None:
            self.set_initial_state()
        assert self._init is not None
        return self._init

    # ------------------------------------------------------------------ inputs
    @property
    def input_spec(self) -> InputSpec:
        """What :meth:`estimate` reads: the kit's IMUs (or MIMUs) with orientation and
        acceleration at the trained rate."""
        return InputSpec.from_kit("PIP", self.kit_name, ("orientation", "acceleration"),
                                  sensor_names=tuple(self.sensor_names), kinds={"imu": ("imu", "mimu"), "mimu": ("imu", "mimu")},
                                  rates={"imu": self.fps, "mimu": self.fps})

    def _bone_orientations(self, rec: Any) -> Any:
        """The checked, canonical recording with bone orientations (module doc): the method's
        own step of :func:`~wearpose.estimators.inputs.prepare`."""
        meta = rec.meta or {}
        if meta.get("orientation_frame") == "segment":
            return rec
        # start-up: wearpose.calibration adds ~470 ms to importing this module
        from wearpose.calibration import CalibrationResult, apply_calibration, calibrate

        cal = meta.get("calibration")
        if isinstance(cal, dict) and cal.get("method") in ("tpose", "ipose"):
            return apply_calibration(rec, CalibrationResult.from_dict(cal))
        if self.calibration_window is not None:
            res = calibrate(rec.select(self.sensor_names), "tpose", body=None, window=self.calibration_window)
            return apply_calibration(rec, res)
        warnings.warn("PIP: recording is neither calibrated nor marked orientation_frame='segment'; using the IMU "
                      "orientations as bone orientations", stacklevel=5)
        return rec

    def _inputs(self, recording: Any) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        x = prepare(recording, self.input_spec, before_grid=self._bone_orientations, nan_to_zero=("acceleration",))
        subj = recording.subject or {}
        if subj.get("betas") is not None:
            self.betas = torch.as_tensor(np.asarray(subj["betas"], dtype=np.float32)).reshape(10)
        return x.channels["acceleration"], x.channels["orientation"], x.valid

    # ------------------------------------------------------------------ outputs
    def _decode(self, out: dict[str, torch.Tensor], root: torch.Tensor) -> dict[str, torch.Tensor]:
        """Network output ``(T, ...)`` + pelvis orientation ``(T, 3, 3)`` -> local pose
        ``(T, 24, 3, 3)``, world joint velocities ``(T, 24, 3)`` m/s, contact probabilities ``(T, 2)``."""
        T = root.shape[0]
        glob = torch.cat([torch.eye(3).expand(T, 1, 3, 3), rot6d_to_matrix(out["rot6"].reshape(T, 23, 6))], 1)
        glob = root[:, None] @ glob
        vel = (root[:, None] @ out["vel"].reshape(T, 24, 3, 1)).squeeze(-1) * self.config.vel_scale
        return {"pose": global_to_local(glob), "vel": vel, "contact": torch.sigmoid(out["contact_logit"])}

    def _decode_one(self, out: dict[str, np.ndarray], root: np.ndarray) -> dict[str, torch.Tensor]:
        """:meth:`_decode` of one frame in numpy (``out`` from :class:`NumpyStepper`, ``root``
        ``(3, 3)``): ``pose`` ``(1, 24, 3, 3)``, ``vel`` ``(1, 24, 3)``, ``contact`` ``(1, 2)``."""
        d6 = out["rot6"].reshape(23, 6).astype(np.float64)
        a1, a2 = d6[:, :3], d6[:, 3:]
        b1 = a1 / np.linalg.norm(a1, axis=1, keepdims=True)
        b2 = a2 - (b1 * a2).sum(1, keepdims=True) * b1
        b2 /= np.linalg.norm(b2, axis=1, keepdims=True)
        glob = np.empty((24, 3, 3))
        glob[0] = root
        glob[1:] = root @ np.stack([b1, b2, np.cross(b1, b2)], axis=-1)  # Gram-Schmidt, columns (rot6d_to_matrix)
        local = np.swapaxes(glob[self._parents_np], 1, 2) @ glob
        local[0] = root
        vel = (out["vel"].reshape(24, 3).astype(np.float64) @ root.T) * self.config.vel_scale
        contact = 1.0 / (1.0 + np.exp(-out["contact_logit"].astype(np.float64)))
        return {"pose": torch.from_numpy(local.astype(np.float32))[None], "vel": torch.from_numpy(vel.astype(np.float32))[None],
                "contact": torch.from_numpy(contact.astype(np.float32))[None]}

    def _physics_optimizer(self) -> Any:
        """The optimizer for the current shape and PD option (the character, costly to build, is
        kept while the shape stays the same)."""
        # start-up: wearpose.physics adds ~240 ms to importing this module
        from wearpose.physics import PhysicsCharacter, PhysicsConfig, PhysicsOptimizer

        shape = tuple(self.betas.tolist())
        if self._char is None or self._char[0] != shape:
            self._char = (shape, PhysicsCharacter.from_body(self.body, self.betas))
            self._optimizer = None
        key = (self.dual_pd, repr(sorted(self.physics_options.items())))  # cheap per frame: no config built
        if self._optimizer is None or getattr(self._optimizer, "_pip_key", None) != key:
            cfg = PhysicsConfig(fps=self.fps, dual_pd=self.dual_pd, **self.physics_options)
            self._optimizer = PhysicsOptimizer(self._char[1], cfg)
            self._optimizer._pip_key = key
        return self._optimizer

    def _use_physics(self) -> bool:
        if self.physics and not physics_available():
            warnings.warn("PIP: wearpose.physics is not available; running without physics", stacklevel=3)
            self.physics = False
        return self.physics

    # ------------------------------------------------------------------ offline
    @torch.no_grad()
    def estimate(self, recording: Any) -> PoseTrack:
        """Offline estimate: the causal chain over the whole sequence (identical to stepping
        :meth:`step` frame by frame), then physics frame by frame or root-velocity integration."""
        acc, ori, valid = self._inputs(recording)
        return self.estimate_tensors(acc, ori, valid)

    @torch.no_grad()
    def estimate_tensors(self, acc: torch.Tensor, ori: torch.Tensor, valid: torch.Tensor | None = None) -> PoseTrack:
        """:meth:`estimate` on raw tensors: ``acc`` ``(T, 6, 3)`` free acceleration (world,
        m/s^2), ``ori`` ``(T, 6, 3, 3)`` bone orientations, kit order; ``valid`` ``(T, 6)``."""
        T = acc.shape[0]
        valid = torch.ones(T, 6, dtype=torch.bool) if valid is None else valid
        init = self._initial()
        self.model.eval()
        x = imu_features(acc, ori, self.config.acc_scale).to(self.device)
        t0 = time.perf_counter()
        states = self._start_states()
        out, _ = self.model(x[None], states)
        kin_ms = (time.perf_counter() - t0) * 1000 / max(T, 1)
        out = {k: v[0].cpu() for k, v in out.items()}
        dec = self._decode(out, ori[:, 5])
        extras: dict[str, Any] = {"frame": "world", "method": self.name, "contacts": dec["contact"],
                                  "joint_vel": dec["vel"], "kin_ms_per_frame": kin_ms, "physics": False}
        if self._use_physics():
            opt = self._physics_optimizer()
            opt.reset(init["pose"], init["trans"])
            poses, trans, tau, grf, flags, qp, pen = [], [], [], [], [], [], []
            for t in range(T):
                st = opt.step(dec["pose"][t], dec["vel"][t], dec["contact"][t])
                poses.append(torch.as_tensor(st.pose_local, dtype=torch.float32))
                trans.append(torch.as_tensor(st.trans, dtype=torch.float32))
                tau.append(torch.as_tensor(st.torques, dtype=torch.float32))
                grf.append(torch.as_tensor(st.grf, dtype=torch.float32))
                flags.append(torch.as_tensor(np.asarray(st.contacts, dtype=bool)))
                qp.append(float(st.qp_ms))
                pen.append(float(st.penetration_m))
            pose, tr = torch.stack(poses), torch.stack(trans)
            extras.update(physics=True, dual_pd=self.dual_pd, torques=torch.stack(tau), grf=torch.stack(grf),
                          contact_flags=torch.stack(flags), qp_ms=torch.tensor(qp), penetration_m=torch.tensor(pen),
                          kinematic_pose=dec["pose"])
        else:
            pose = dec["pose"]
            step = dec["vel"][:, 0] / self.fps
            tr = init["trans"] + torch.cumsum(torch.cat([torch.zeros(1, 3), step[1:]]), 0)
        return PoseTrack(pose, self.betas.clone(), tr, valid.all(1), self.fps, extras=extras)

    def _start_states(self) -> list[Any]:
        init = self._initial()
        if not (self.learned_init and self.config.learned_init):
            return [None] * 5
        return self.model.initial_states(init["leaf"][None].to(self.device), init["vel"][None].to(self.device))

    # ------------------------------------------------------------------ online
    def reset(self) -> None:
        self._states: list[Any] | None = None
        self._input = OnlineInput(self.sensor_names, ("acceleration", "orientation"), who="PIP",
                                  nan_to_zero=("acceleration",))
        self._trans: torch.Tensor | None = None
        self._started_physics = False
        self._integrating = False
        self._stepper_started = False

    @torch.no_grad()
    def step(self, frame: SensorFrame) -> PoseFrame:
        """One 60 fps frame of bone orientations and free accelerations (calibrated: see
        :meth:`set_initial_state` and the module doc); the LSTM states carry over."""
        (a, R), v = self._input(frame)
        return self.step_tensors(a, R, bool(v.all()), frame.timestamp)

    @torch.no_grad()
    def step_tensors(self, acc: torch.Tensor, ori: torch.Tensor, valid: bool = True, timestamp: float = 0.0) -> PoseFrame:
        """:meth:`step` on tensors ``acc`` ``(6, 3)``, ``ori`` ``(6, 3, 3)`` (kit order, bone orientations)."""
        init = self._initial()
        if self._states is None:
            self.model.eval()
            self._states = self._start_states()
            self._trans = init["trans"].clone()
        t0, c0 = time.perf_counter(), time.thread_time()
        x = imu_features(acc, ori, self.config.acc_scale)
        if self.fast_step and self.device.type == "cpu":
            if self._stepper is None or self._stepper[0] is not self.model:
                self._stepper = (self.model, NumpyStepper(self.model))
            stepper = self._stepper[1]
            if not self._stepper_started:
                stepper.set_states(self._states)
                self._stepper_started = True
            dec = self._decode_one(stepper.step(x.numpy().astype(np.float32, copy=False)), ori[5].numpy())
        else:
            out, self._states = self.model(x[None, None].to(self.device), self._states)
            dec = self._decode({k: v[0].cpu() for k, v in out.items()}, ori[5:6])
        # wall and CPU time of this thread (the latter is less inflated on a busy machine)
        kin_ms, kin_cpu_ms = (time.perf_counter() - t0) * 1000, (time.thread_time() - c0) * 1000
        extras: dict[str, Any] = {"frame": "world", "contacts": dec["contact"][0], "joint_vel": dec["vel"][0],
                                  "kin_ms": kin_ms, "kin_cpu_ms": kin_cpu_ms}
        if self._use_physics():
            opt = self._physics_optimizer()
            if not self._started_physics:
                opt.reset(init["pose"], init["trans"])
                self._started_physics = True
            t1 = time.perf_counter()
            st = opt.step(dec["pose"][0], dec["vel"][0], dec["contact"][0])
            extras["physics_ms"] = (time.perf_counter() - t1) * 1000
            extras["physics_cpu_ms"] = float(getattr(st, "step_cpu_ms", float("nan")))
            pose = torch.as_tensor(st.pose_local, dtype=torch.float32)
            trans = torch.as_tensor(st.trans, dtype=torch.float32)
            extras.update(torques=torch.as_tensor(st.torques), grf=torch.as_tensor(st.grf), contact_flags=st.contacts,
                          qp_ms=float(st.qp_ms), penetration_m=float(st.penetration_m))
        else:
            pose = dec["pose"][0]
            assert self._trans is not None
            # Frame 0 sits at the known initial translation; integration starts at frame 1
            # (as in the offline path).
            if self._integrating:
                self._trans = self._trans + dec["vel"][0, 0] / self.fps
            self._integrating = True
            trans = self._trans.clone()
        return PoseFrame(pose, self.betas.clone(), trans, valid, timestamp, extras=extras)

"""``EmposeEstimator``: the LGD-RNN behind the :class:`~wearpose.estimators.Estimator` protocol.

Input: EM 6-DoF sensors of kit ``em12`` / ``em6`` relative to the EM source (DESIGN, EM
canonical form) at the trained rate, plus the subject's sensor offsets ``O_p`` in
``recording.subject["offsets"]`` (``{"sensors": [...], "rotation": (S, 3, 3), "translation_mean_m": (S, 3)}``; EM-POSE
assumes calibrated offsets, Sec. 5.3). Missing offsets fall back to identity with a warning.

Masked input: a dropped sensor sample is held at its last valid value, and frames where any
sensor was dropped are marked ``valid = False`` in the output (EM-POSE evaluates only frames
with all sensors, Sec. 6.2).

Output frame: ``extras["frame"] = "em_source"``: the root orientation is relative to the EM
source frame (the source rides on the lower back); no translation is estimated (Sec. 5.1).
"""

from __future__ import annotations

import warnings
from dataclasses import replace
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import torch

from wearpose.errors import ConfigError, ShapeError
from wearpose.estimators.base import Estimator, PoseFrame, PoseTrack, SensorFrame
from wearpose.estimators.checkpoint import Checkpoint, CheckpointMismatchError, NetworkCheckpointing, load_checkpoint
from wearpose.estimators.empose.config import INFERENCE_FIELDS, EmposeConfig
from wearpose.estimators.empose.model import LGDRNN, PRED_JOINTS, VirtualSensors, module_version, sensor_features
from wearpose.estimators.empose.refine import (
    Refined, measures_turn, recording_turn, refine_frames, require_threshold, turn_sums, turn_terms, turned,
)
from wearpose.estimators.empose.shapefit import ShapeFit, fit_frames, fit_shape
from wearpose.estimators.inputs import InputSpec, OnlineInput, prepare
from wearpose.estimators.registry import register_estimator
from wearpose.estimators.seeding import init_seed, seeded
from wearpose.estimators.trainmix import mix_clause
from wearpose.geometry import matrix_to_rot6d
from wearpose.sensors import get_kit, resolve_sites


def _sites(kit_name: str, body: Any) -> tuple[list[str], str]:

    kit = get_kit(kit_name)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sites, _ = resolve_sites(kit, body.site_names, body.asset_id)
    return [sites[n] for n in kit.sensor_names], sites["<em_source>"]


class _OnlineStep(torch.nn.Module):
    """One online frame of the LGD-RNN (LSTM step + closed-form LGD updates), batch 1, for tracing
    (a module, so the weights enter the trace as parameters)."""

    def __init__(self, model: LGDRNN, sensors: VirtualSensors) -> None:
        super().__init__()
        self.m = model
        self.sensors = sensors

    def forward(self, x, p, R, offR, offt, h, c):  # noqa: ANN001, ANN201 - traced
        omega0, (h2, c2) = self.m.initial_step(x[None], (h, c))
        last = self.m._refine_lean(omega0, x[None], p[None], R[None], offR[None], offt[None], self.sensors)[-1]
        return last["local_rot"][0], last["betas"][0], last["rec"][0], h2, c2


@register_estimator("empose")
class EmposeEstimator(NetworkCheckpointing, Estimator):
    """LGD-RNN estimator (see module doc).

    Args:
        config: :class:`EmposeConfig`.
        body: :class:`~wearpose.body.BodyModel` (default: the embedded asset).
        device: torch device.
    """

    name = "empose"
    causal = True
    lookahead = 0

    def __init__(self, config: EmposeConfig | None = None, body: Any = None, device: str | torch.device = "cpu") -> None:
        self.init_state(config or EmposeConfig.preset("cpu", 12), body, device)
        sites, src = _sites(self.kit_name, self.body)
        self.sites = {**dict(zip(self.sensor_names, sites)), "<em_source>": src}
        self.sensors = VirtualSensors(self.body, sites, src)
        with seeded(init_seed(self.config.seed)):  # initial weights: a function of the seed (issue 24)
            self.model = LGDRNN(self.config, len(self.sensor_names)).to(self.device)
        self._state: tuple[torch.Tensor, torch.Tensor] | None = None
        self._input = OnlineInput(self.sensor_names, ("position", "orientation"), who=self.name)
        self._offsets: tuple[torch.Tensor, torch.Tensor] | None = None
        self._traced: tuple[Any, Any] | None = None
        self._fit_buffer: list[dict[str, torch.Tensor]] = []  # online shape fit: the first valid frames
        self._shape: torch.Tensor | None = None  # online shape fit: the fitted shape, once fitted
        self._turn_sum: torch.Tensor | None = None  # online recording centre: the measured frames' turn_terms summed
        self._turn_count = 0  # online recording centre: valid frames seen
        self._turn_measured = False  # online recording centre: the last step added its solve
        self._turn: torch.Tensor | None = None  # online recording centre: the prior's turn, once measured

    # ------------------------------------------------------------------ checkpoints
    def checkpoint(self, meta: dict[str, Any] | None = None, train_state: dict[str, Any] | None = None) -> Checkpoint:
        # The sensor sites go with the weights: loading on another body asset must put them where they were.
        return super().checkpoint({"sites": self.sites, **(meta or {})}, train_state)

    @classmethod
    def from_checkpoint(cls, ckpt: Checkpoint, *, kit: str | None = None, body: Any = None,
                        device: str | torch.device = "cpu", path: str | Path = "<checkpoint>") -> EmposeEstimator:
        body = cls.check_checkpoint(ckpt, kit=kit, body=body, path=path)
        trained = {k: v for k, v in ckpt.config.items() if k not in INFERENCE_FIELDS}  # today's inference defaults
        est = cls(EmposeConfig.from_dict(trained), body=body, device=device)
        want = ckpt.meta.get("sites")
        if want and want != est.sites:
            diff = {k: f"{want.get(k)} -> {est.sites.get(k)}" for k in sorted(set(want) | set(est.sites))
                    if want.get(k) != est.sites.get(k)}
            raise CheckpointMismatchError(f"{path}: body asset {est.body_asset_id!r} puts the sensors of kit "
                                          f"{est.kit_name!r} on other sites than at training time (trained -> now): {diff}")
        return est.restore(ckpt)

    @classmethod
    def load(cls, path: str | Path, *, kit: str | None = None, body: Any = None,
             map_location: str | torch.device = "cpu") -> EmposeEstimator:
        return cls.from_checkpoint(load_checkpoint(path, map_location), kit=kit, body=body, device=map_location, path=path)

    def fit(self, *args: Any, **kwargs: Any) -> Any:
        """Train (see :func:`wearpose.estimators.empose.train.train_empose`)."""
        from wearpose.estimators.empose.train import train_empose  # cycle: train and twostage import this module at their top

        return train_empose(self, *args, **kwargs)

    @classmethod
    def training_data_description(cls, config: Mapping[str, Any]) -> str | None:
        """The card sentence (:meth:`Estimator.training_data_description`) of
        :func:`wearpose.estimators.empose.data.build_split`; shared by the Table 2 baselines and
        the two-stage model, which train on the same data (plus its sensor removal)."""
        cfg = EmposeConfig.from_dict(dict(config))
        noise = {"default": "default EM noise", "none": "no noise"}[cfg.train_noise]
        offsets = {"random": "random subject offsets per clip",
                   "rot": "random subject offset rotations per clip, translations zero",
                   "none": "no subject offsets"}[cfg.offsets]
        twostage = cfg.model == "twostage"
        # the two-stage mapper sees a dropped sample as zeros plus an availability flag, the others a held value
        dropped = ("dropped frames as zeros with an availability flag" if twostage else
                   "dropped frames held at the last valid value")
        text = (f"virtual EM sensors, kit {cfg.kit} (wearpose.sensors.simulate, {noise}, {offsets}) at {cfg.rate:g} Hz, "
                f"relative to the EM source on the lower back" + (f", {dropped}" if cfg.train_noise == "default" else "")
                + f"; windows of {cfg.seq_len} frames every {cfg.window_stride}")
        if cfg.inputs != "both":  # the Table 3 "pos only" / "ori only" ablations
            text += f"; network input: sensor {cfg.inputs}s only"
        if twostage:
            from wearpose.estimators.empose.twostage import MAX_REMOVED, P_REMOVE  # cycle: train and twostage import this module at their top

            text += (f"; the joint mapper trains with 1-{MAX_REMOVED} sensors removed (zeros, flag off) for half of "
                     f"the window in {P_REMOVE:.0%} of the windows")
        return text + mix_clause(cfg)

    # ------------------------------------------------------------------ inputs
    def _offsets_from(self, recording: Any) -> tuple[torch.Tensor, torch.Tensor]:
        S = len(self.sensor_names)
        if self.config.offsets == "none":
            # The "no [R|t]" ablation was trained with sensors on the skin sites themselves: it has
            # no notion of offsets, so it reconstructs with identity ones whatever the recording says.
            return torch.eye(3).expand(S, 3, 3).clone(), torch.zeros(S, 3)
        off = (recording.subject or {}).get("offsets") if recording is not None else None
        if off and not all(k in off for k in ("rotation", "translation_mean_m")):
            raise ShapeError(f"subject['offsets'] needs 'rotation' (S, 3, 3) and 'translation_mean_m' (S, 3); got keys {sorted(off)}")
        if not off and self.config.refine_steps > 0:
            # The refinement fits the pose to the sensors through their offsets: with identity ones
            # it would bend the joints to explain the mounting, not refine the pose.
            where, fix = ((getattr(recording, "origin", None) or "recording", "calibrate them (wearpose calibrate "
                           "RECORDING --method empose-offsets, docs/calibration.md)") if recording is not None else
                          ("online step", "give them with set_offsets(R, t) before the first step"))
            raise ConfigError(f"{where}: EM-POSE refine_steps={self.config.refine_steps} needs the sensors' offsets "
                              f"(subject['offsets']) and has none; {fix}, or turn the refinement off "
                              "(--set refine_steps=0)")
        if not off:
            warnings.warn("EM-POSE: recording has no subject offsets (subject['offsets']); using identity "
                          "offsets (the 'no [R|t]' setting), expect a large error", stacklevel=3)
            return torch.eye(3).expand(S, 3, 3).clone(), torch.zeros(S, 3)
        names = list(off.get("sensors", self.sensor_names))
        idx = [names.index(n) for n in self.sensor_names if n in names]
        if len(idx) != S:
            raise ShapeError(f"subject offsets name sensors {names}; estimator needs {list(self.sensor_names)}")
        # Keys of wearpose.recording (from_empose / from_simulation): rotation (S, 3, 3) sensor ->
        # site frame, translation_mean_m (S, 3) in the site frame.
        R = torch.as_tensor(np.asarray(off["rotation"], dtype=np.float32))[idx]
        t = torch.as_tensor(np.asarray(off["translation_mean_m"], dtype=np.float32))[idx]
        if self.config.offsets == "rot":
            t = torch.zeros_like(t)  # "no t" ablation: trained without translation offsets, reconstructs without
        return R, t

    def set_offsets(self, R: torch.Tensor, t: torch.Tensor) -> None:
        """Subject offsets for :meth:`step`: ``R`` ``(S, 3, 3)``, ``t`` ``(S, 3)`` m (kit order).

        Raises:
            ConfigError: the refinement's prior is centred on the whole recording
                (``refine_centre="recording"`` with ``refine_centre_frames=0``), which an online
                step does not have.
        """
        self._refuse_online_centre()
        self._offsets = (torch.as_tensor(R, dtype=torch.float32), torch.as_tensor(t, dtype=torch.float32))

    def _refuse_online_centre(self) -> None:
        """Online steps cannot centre the prior on the whole recording: refuse before the first
        step (a server then refuses the subject at its hello), naming the ways out."""
        cfg = self.config
        if cfg.refine_steps > 0 and cfg.refine_centre == "recording" and cfg.refine_centre_frames == 0:
            raise ConfigError("online step: EM-POSE refine_centre='recording' with refine_centre_frames=0 turns the "
                              "refinement's prior by the whole recording, which a step does not have; measure it as "
                              "the stream goes (--set refine_centre_frames=1 --set refine_centre_every=1: each frame "
                              "turned by the turn over the frames so far), estimate the recording "
                              "offline, or set refine_centre=learned (--set refine_centre=learned)")

    @property
    def input_spec(self) -> InputSpec:
        """What :meth:`estimate` reads: the kit's EM sensors relative to the source, at the trained rate."""
        return InputSpec.from_kit("EM-POSE", self.kit_name, ("position", "orientation"),
                                  sensor_names=tuple(self.sensor_names), rates={"em6dof": self.fps},
                                  reference="source")

    def _measurements(self, recording: Any, hold: bool = True) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Kit sensors of a recording (:func:`~wearpose.estimators.inputs.prepare`): positions
        ``(T, S, 3)`` m, orientations ``(T, S, 3, 3)`` (dropped samples held at the last valid
        value when ``hold``, NaN otherwise) and ``valid`` ``(T, S)``."""
        x = prepare(recording, self.input_spec, hold=hold)
        return x.channels["position"], x.channels["orientation"], x.valid

    # ------------------------------------------------------------------ offline
    @torch.no_grad()
    def estimate(self, recording: Any, chunk: int = 2048) -> PoseTrack:
        """Offline estimate (the causal network run over the whole sequence).

        Returns a :class:`PoseTrack` with ``trans=None`` and ``extras["frame"] = "em_source"``;
        ``extras["rec_loss"]`` ``(T,)`` is L_r of the final estimate. With the refinement on
        (``config.refine_steps > 0``, :meth:`_refine`) also ``extras["rec_loss_learned"]``
        ``(T,)`` (L_r of the learned estimate) and ``extras["refined"]`` ``(T,)`` bool (the
        frames the gate refined). With the shape fit on (``config.shape_fit_frames > 0``,
        :mod:`~wearpose.estimators.empose.shapefit`): ``betas`` is the shape fitted to
        ``shape_fit_frames`` frames spread over the recording, every frame keeps its learned pose
        and is scored (``rec_loss``, the refinement) with that shape; also
        ``extras["rec_loss_learned"]`` and ``extras["shape_fit"]`` (:meth:`ShapeFit.summary`).
        """
        p, R, valid = self._measurements(recording)
        offR, offt = self._offsets_from(recording)
        self.model.eval()
        dev = self.device
        x = sensor_features(p, R).to(dev)
        omega0, _ = self.model.initial(x[None])
        omega0 = omega0[0]
        T, S = p.shape[:2]
        spans = [(a, min(T, a + chunk)) for a in range(0, T, chunk)]
        lasts = []
        for a, b in spans:
            n = b - a
            lasts.append(self.model.refine(omega0[a:b], x[a:b], p[a:b].to(dev), R[a:b].to(dev),
                                           offR.to(dev).expand(n, S, 3, 3), offt.to(dev).expand(n, S, 3), self.sensors,
                                           train=False)[-1])
        ok = valid.all(1)
        fit = self._fit_shape(lasts, ok, p, R, offR, offt) if self.config.shape_fit_frames > 0 else None
        turns = self._recording_turn(spans, lasts, ok, p, R, offR, offt, fit)
        rots, betas, rec, learned, gated = [], [], [], [], []
        for (a, b), last in zip(spans, lasts):
            lrot, lb, lrec = last["local_rot"].detach(), last["betas"].detach(), last["rec"].detach()
            if fit is not None:  # every frame's learned pose, scored with the fitted shape
                lb = fit.betas.to(dev).expand(b - a, -1)
            if turns is not None:  # the prior's centre: the learned pose turned where a turn is in force
                lrot = self._turned_span(lrot, a, *turns)
            if fit is not None or turns is not None:
                lrec = self._rec(lrot, lb, p[a:b].to(dev), R[a:b].to(dev), offR.to(dev), offt.to(dev))
            ref = self._refine(lrot, lb, lrec, p[a:b].to(dev), R[a:b].to(dev), offR.to(dev), offt.to(dev))
            rots.append(ref.local_rot)
            betas.append(last["betas"].detach())
            rec.append(ref.rec)
            learned.append(last["rec"].detach())
            gated.append(ref.gated)
        local_rot, b_all = torch.cat(rots).cpu(), torch.cat(betas).cpu()
        beta = (b_all[ok] if bool(ok.any()) else b_all).mean(0)  # one shape per sequence (Sec. 5.3)
        extras = {"frame": "em_source", "rec_loss": torch.cat(rec).cpu(), "method": self.name, "betas_per_frame": b_all}
        if self.config.refine_steps > 0 or fit is not None:
            extras["rec_loss_learned"] = torch.cat(learned).cpu()
        if self.config.refine_steps > 0:
            extras["refined"] = torch.cat(gated).cpu()
        if fit is not None:
            beta = fit.betas.cpu()
            extras["shape_fit"] = fit.summary()
        return PoseTrack(local_rot, beta, None, ok, self.fps, extras=extras)

    def _recording_turn(self, spans: list[tuple[int, int]], lasts: list[dict[str, torch.Tensor]], ok: torch.Tensor,
                        p: torch.Tensor, R: torch.Tensor, offR: torch.Tensor, offt: torch.Tensor,
                        fit: ShapeFit | None) -> tuple[torch.Tensor, torch.Tensor] | None:
        """The prior centre's turns when the refinement is on with ``refine_centre="recording"``
        (:func:`~wearpose.estimators.empose.refine.recording_turn`; ``ok`` ``(T,)`` the frames with
        every sensor valid, ``spans`` the chunks, ``lasts`` their learned outputs, ``fit`` the
        shape fit if on), as ``(starts (M,) long, turns (M, NUM_PRED, 3, 3))`` in frame order, turn
        i used from frame ``starts[i]`` until the next one starts: the whole recording's turn from
        frame 0; with ``refine_centre_frames = n > 0`` the first n valid frames' turn from the n-th
        on, and with ``refine_centre_every = k > 0`` a new turn at every k-th valid frame after it,
        over every frame measured so far: what a stream (:meth:`step`) has. None when off, when no
        frame has every sensor, or there are fewer than n."""
        cfg = self.config
        if cfg.refine_steps == 0 or cfg.refine_centre != "recording":
            return None
        n, k = cfg.refine_centre_frames, cfg.refine_centre_every
        if n == 0 and k > 0:
            raise ConfigError(f"EM-POSE refine_centre_every={k} adds frames to the turn of the first "
                              "refine_centre_frames, which is 0 (the whole recording); give it, e.g. "
                              "--set refine_centre_frames=1 (with every=1: the running turn), or set "
                              "refine_centre_every=0")
        if n and int(ok.sum()) < n:
            return None  # a stream this short never gets the turn either
        pos = ok.long().cumsum(0) - 1  # each frame's place among the valid ones
        measured = ok & measures_turn(pos, n, k) if n else ok
        dev, carry, starts, turns = self.device, None, [], []
        for (a, b), last in zip(spans, lasts):
            keep = measured[a:b]
            m = int(keep.sum())
            if m == 0:
                continue
            kd = keep.to(dev)
            lb = fit.betas.to(dev).expand(m, -1) if fit is not None else last["betas"].detach()[kd]
            args = (self.sensors.lean(), last["local_rot"].detach()[kd], lb, p[a:b][keep].to(dev), R[a:b][keep].to(dev),
                    offR.to(dev), offt.to(dev))
            if n == 0:  # one sum per chunk: no frame's share is kept
                s = turn_sums(*args, steps=cfg.refine_steps, rec_weights=self.model.rec_weights)
                carry = s if carry is None else carry + s
                continue
            cum = turn_terms(*args, steps=cfg.refine_steps, rec_weights=self.model.rec_weights).cumsum(0)
            if carry is not None:
                cum = cum + carry
            carry = cum[-1]
            frames = a + keep.nonzero().squeeze(1)
            new = pos[frames] >= n - 1  # from the n-th valid frame on, each measured frame renews the turn
            starts.append(frames[new])
            turns.append(recording_turn([cum[new.to(dev)]]))  # one turn per renewal
        if carry is None:
            return None
        if n == 0:
            return torch.zeros(1, dtype=torch.long), recording_turn([carry])[None]
        return torch.cat(starts), torch.cat(turns)

    @staticmethod
    def _turned_span(lrot: torch.Tensor, a: int, starts: torch.Tensor, turns: torch.Tensor) -> torch.Tensor:
        """``lrot`` ``(N, 24, 3, 3)``, frames ``a .. a + N - 1`` of the recording, with each frame
        turned by the turn in force there (:meth:`_recording_turn`'s ``starts`` ``(M,)`` and
        ``turns`` ``(M, NUM_PRED, 3, 3)``; frames before the first start keep the learned pose);
        ``lrot`` itself when no turn reaches these frames."""
        i = torch.searchsorted(starts, torch.arange(a, a + lrot.shape[0]), right=True) - 1  # -1: before the first
        on = i >= 0
        if not bool(on.any()):
            return lrot
        out = lrot.clone()
        sel = on.to(lrot.device)
        out[sel] = turned(lrot[sel], turns[i[on].to(turns.device)])
        return out

    def _rec(self, local_rot: torch.Tensor, betas: torch.Tensor, p: torch.Tensor, R: torch.Tensor,
             offR: torch.Tensor, offt: torch.Tensor) -> torch.Tensor:
        """L_r ``(N,)`` of poses ``(N, 24, 3, 3)`` with shapes ``betas`` ``(N, 10)`` against the
        measurements ``p`` ``(N, S, 3)`` m, ``R`` ``(N, S, 3, 3)`` (the closed-form kernel)."""
        u = matrix_to_rot6d(local_rot[:, list(PRED_JOINTS)]).reshape(local_rot.shape[0], -1)
        return self.sensors.lean().forward(torch.cat([u, betas], -1), p, R, offR, offt, self.model.rec_weights)["rec"]

    def _fit_shape(self, lasts: list[dict[str, torch.Tensor]], ok: torch.Tensor, p: torch.Tensor, R: torch.Tensor,
                   offR: torch.Tensor, offt: torch.Tensor, spread: bool = True) -> ShapeFit | None:
        """The per-recording shape fit (:func:`~wearpose.estimators.empose.shapefit.fit_shape`)
        on ``config.shape_fit_frames`` of the frames where ``ok`` ``(T,)`` (every sensor valid),
        spread over them or the first ones (:func:`fit_frames`); ``lasts`` the learned outputs
        (dicts of :meth:`LGDRNN.refine`'s last iteration) covering the ``T`` frames in order,
        measurements ``p`` ``(T, S, 3)`` m and ``R`` ``(T, S, 3, 3)``. None when no frame has
        every sensor (nothing to fit: the learned shape stays)."""
        idx = fit_frames(ok, self.config.shape_fit_frames, spread)
        if idx.numel() == 0:
            return None
        cat = {k: torch.cat([o[k].detach() for o in lasts]).index_select(0, idx.to(self.device))
               for k in ("local_rot", "betas", "rec")}
        dev = self.device
        return fit_shape(self.sensors.lean(), cat["local_rot"], cat["betas"], cat["rec"], p[idx].to(dev),
                         R[idx].to(dev), offR.to(dev), offt.to(dev), steps=self.config.shape_fit_steps,
                         prior=self.config.shape_fit_prior, rec_weights=self.model.rec_weights)

    def _refine(self, local_rot: torch.Tensor, betas: torch.Tensor, rec: torch.Tensor, p: torch.Tensor,
                R: torch.Tensor, offR: torch.Tensor, offt: torch.Tensor) -> Refined:
        """The measurement-consistency refinement of the learned estimate
        (:func:`~wearpose.estimators.empose.refine.refine_frames` with this config's
        ``refine_steps``, ``refine_threshold``, ``refine_weight``): ``local_rot`` ``(N, 24, 3, 3)``,
        ``betas`` ``(N, 10)``, ``rec`` ``(N,)``, measurements ``p`` ``(N, S, 3)`` m and ``R``
        ``(N, S, 3, 3)``, offsets ``(S, 3, 3)`` and ``(S, 3)`` m. Off (``refine_steps == 0``):
        the inputs themselves."""
        cfg = self.config
        require_threshold(cfg.refine_steps, cfg.refine_threshold)
        if cfg.refine_steps == 0:
            return Refined(local_rot, rec, torch.zeros_like(rec, dtype=torch.bool))
        return refine_frames(self.sensors.lean(), local_rot, betas, rec, p, R, offR, offt, steps=cfg.refine_steps,
                             threshold=float(cfg.refine_threshold), weight=cfg.refine_weight,
                             solver=cfg.refine_solver, rec_weights=self.model.rec_weights)

    @torch.no_grad()
    def to_world(self, track: PoseTrack, source_R: torch.Tensor, source_p: torch.Tensor) -> PoseTrack:
        """Place a source-frame track in the world, given the EM source's world pose.

        The body is posed in the source frame (``extras["frame"] == "em_source"``); the rigid
        transform that takes the estimated source *site* (:meth:`BodyModel.sites` of the
        estimate) onto the given source pose moves the whole body: root orientation
        ``R_w R_root`` and translation ``R_w (J_0 - p_site) + p_src - J_0`` (SMPL rotates about the
        rest root joint ``J_0``), with ``R_w = R_src R_site^T``.

        Args:
            track: an :meth:`estimate` result.
            source_R: ``(T, 3, 3)`` source frame -> world; source_p: ``(T, 3)`` m, world (e.g. the
                simulator's ``em_source``, or a tracked source).

        Returns:
            a new :class:`PoseTrack` with ``trans`` set and ``extras["frame"] = "world"``.
        """
        src = self.sites["<em_source>"]
        pose = track.local_rot.to(self.device)
        so = self.body.sites(pose, track.betas.to(self.device), None, [src])
        R_site, p_site = so.rotations[:, 0].cpu(), so.positions[:, 0].cpu()
        R_w = source_R.to(R_site) @ R_site.transpose(-1, -2)
        J0 = self.body.rest_joints(track.betas.to(self.device))[0].cpu()
        trans = (R_w @ (J0 - p_site).unsqueeze(-1)).squeeze(-1) + source_p.to(R_site) - J0
        rot = track.local_rot.clone()
        rot[:, 0] = R_w @ rot[:, 0]
        return PoseTrack(rot, track.betas.clone(), trans, track.valid.clone(), track.fps, track.uncertainty,
                         {**track.extras, "frame": "world"})

    # ------------------------------------------------------------------ settings
    def set_iterations(self, n: int) -> None:
        """Run ``n`` LGD updates per frame from now on (``config.iterations``, N of Eq. 5).

        The update network is the same at every step, so any N runs; the shipped figures are at
        the N the card states (the trained one). Other values are for timing (e.g. the paper's
        N = 4 with ``wearpose bench latency empose12_cpu --set iterations=4``) or a study of N.
        Resets the online state (the traced step is rebuilt for the new N).

        Raises:
            ConfigError: ``n`` is not a whole number >= 0.
        """
        if isinstance(n, bool) or not isinstance(n, int) or n < 0:
            raise ConfigError(f"EM-POSE iterations: expected a whole number of LGD updates >= 0, got {n!r}")
        self._set_config(iterations=n)

    def _set_config(self, **kw: Any) -> None:
        self.config = replace(self.config, **kw)  # EmposeConfig checks the values
        self.model.cfg = self.config
        self.reset()

    def set_refine_steps(self, n: int) -> None:
        """Refine the gated frames (every frame by default) with ``n`` iterations of
        ``config.refine_solver`` from now on (0 = off; module doc of
        :mod:`~wearpose.estimators.empose.refine`), e.g. ``--set refine_steps=3``.

        Raises:
            ConfigError: ``n`` is not a whole number >= 0.
        """
        self._set_config(refine_steps=n)

    def set_refine_threshold(self, level: float) -> None:
        """The gate of the refinement: frames with L_r above ``level`` are refined (a calibrated
        level, :func:`~wearpose.estimators.empose.refine.calibrate_threshold`)."""
        self._set_config(refine_threshold=float(level))

    def set_refine_weight(self, w: float) -> None:
        """The weight of the refinement's pose prior (pull to the learned estimate)."""
        self._set_config(refine_weight=float(w))

    def set_refine_centre(self, centre: str) -> None:
        """Where the refinement's prior is centred: ``"learned"`` (each frame's learned estimate)
        or ``"recording"`` (turned by the recording's per-joint turn,
        :func:`~wearpose.estimators.empose.refine.recording_turn`, measured on
        ``refine_centre_frames``), e.g. ``--set refine_centre=recording``."""
        self._set_config(refine_centre=centre)

    def set_refine_centre_frames(self, n: int) -> None:
        """The frames the recording centre's turn is measured on: 0 = every valid frame of the
        recording (offline only), n > 0 = the first n valid ones, the turn used from the n-th
        on (online and offline alike), e.g. ``--set refine_centre_frames=1`` with
        ``refine_centre_every=1``: the running turn over every frame so far (docs/empose.md)."""
        self._set_config(refine_centre_frames=n)

    def set_refine_centre_every(self, k: int) -> None:
        """With ``refine_centre_frames = n > 0``: every k-th valid frame after the n-th adds its
        solve to the recording centre's turn, which is renewed there (0 = the first n frames
        only), e.g. ``--set refine_centre_every=1``."""
        self._set_config(refine_centre_every=k)

    def set_refine_solver(self, solver: str) -> None:
        """The refinement's solver: ``"lbfgs"`` or ``"gn"`` (Levenberg-Marquardt Gauss-Newton,
        :func:`~wearpose.estimators.empose.refine.gauss_newton`), e.g. ``--set refine_solver=gn``."""
        self._set_config(refine_solver=solver)

    def set_shape_fit_frames(self, n: int) -> None:
        """Fit one body shape per recording on ``n`` frames from now on (0 = off;
        :mod:`~wearpose.estimators.empose.shapefit`), e.g. ``--set shape_fit_frames=20``.

        Raises:
            ConfigError: ``n`` is not a whole number >= 0.
        """
        self._set_config(shape_fit_frames=n)

    def set_shape_fit_steps(self, n: int) -> None:
        """L-BFGS iterations of the shape fit."""
        self._set_config(shape_fit_steps=n)

    def set_shape_fit_prior(self, w: float) -> None:
        """The weight of the shape fit's prior ``||beta||^2`` (L_r units)."""
        self._set_config(shape_fit_prior=float(w))

    # ------------------------------------------------------------------ online
    def _online_shape(self, rot: torch.Tensor, b: torch.Tensor, rec: torch.Tensor, p: torch.Tensor, R: torch.Tensor,
                      valid: bool) -> tuple[torch.Tensor, torch.Tensor]:
        """The online shape fit for one frame (:meth:`step`): the learned pose ``rot``
        ``(24, 3, 3)``, shape ``b`` ``(10,)`` and L_r ``rec`` ``()`` of a frame with measurements
        ``p`` ``(S, 3)`` m and ``R`` ``(S, 3, 3)``. Buffers the frame while the fit waits for
        ``config.shape_fit_frames`` valid frames, fits on the n-th (:meth:`_fit_shape` on the
        first n); returns the shape to output and the frame's L_r with it."""
        if self._shape is None and valid:
            self._fit_buffer.append({"local_rot": rot[None], "betas": b[None], "rec": rec.reshape(1), "p": p, "R": R})
            if len(self._fit_buffer) >= self.config.shape_fit_frames:
                buf = self._fit_buffer
                fit = self._fit_shape(buf, torch.ones(len(buf), dtype=torch.bool), torch.stack([f["p"] for f in buf]),
                                      torch.stack([f["R"] for f in buf]), *self._offsets, spread=False)
                self._shape, self._fit_buffer = fit.betas, []
        if self._shape is None:
            return b, rec
        offR, offt = self._offsets
        return self._shape, self._rec(rot[None], self._shape[None], p[None], R[None], offR, offt)[0]

    def _online_turn(self, rot: torch.Tensor, b: torch.Tensor, rec: torch.Tensor, p: torch.Tensor, R: torch.Tensor,
                     valid: bool) -> tuple[torch.Tensor, torch.Tensor]:
        """The online recording centre for one frame (:meth:`step`, ``refine_centre="recording"``):
        the learned pose ``rot`` ``(24, 3, 3)`` with shape ``b`` ``(10,)`` and L_r ``rec`` ``()``,
        measurements ``p`` ``(S, 3)`` m and ``R`` ``(S, 3, 3)``. Each of the first
        ``refine_centre_frames`` (n) valid frames adds its prior-free solve
        (:func:`~wearpose.estimators.empose.refine.turn_sums`, one per frame, so no frame pays
        for the others) and the n-th fixes the turn; with ``refine_centre_every = k > 0`` every
        k-th valid frame after it adds its solve and renews the turn. From the n-th frame on the
        prior's centre (and the pose of a frame the gate leaves) is the turned learned pose, as in
        :meth:`estimate`. Returns it and its L_r."""
        cfg = self.config
        n, k = cfg.refine_centre_frames, cfg.refine_centre_every
        offR, offt = self._offsets
        self._turn_measured = False
        if valid:
            c = self._turn_count
            self._turn_count += 1
            if measures_turn(c, n, k):
                self._turn_measured = True
                term = turn_sums(self.sensors.lean(), rot[None], b[None], p[None], R[None], offR, offt,
                                 steps=cfg.refine_steps, rec_weights=self.model.rec_weights)
                self._turn_sum = term if self._turn_sum is None else self._turn_sum + term
                if c >= n - 1:
                    self._turn = recording_turn([self._turn_sum])
        if self._turn is None:
            return rot, rec
        rot = turned(rot[None], self._turn)[0]
        return rot, self._rec(rot[None], b[None], p[None], R[None], offR, offt)[0]

    def reset(self) -> None:
        self._state = None
        self._input = OnlineInput(self.sensor_names, ("position", "orientation"), who=self.name)
        self._fit_buffer, self._shape = [], None
        self._turn_sum, self._turn_count, self._turn = None, 0, None

    def _online_fn(self) -> Any:
        """The per-frame computation (LSTM step + N closed-form LGD updates) as a TorchScript trace
        for batch 1: the same aten ops without Python in between (about 40 % less CPU per
        frame). Built at the first :meth:`step` and rebuilt when the weights, N, device or mode
        change; None when the autograd path applies (axis-angle pose, ``lean_inference`` off)."""
        m = self.model
        if m.rep != "rot6d" or not m.lean_inference:
            return None
        key = (m.cfg.iterations, str(self.device), module_version(m))
        if self._traced is not None and self._traced[0] == key:
            return self._traced[1]
        S, H = len(self.sensor_names), m.cfg.hidden
        self.sensors.lean()
        m.update._fused_layers()  # built outside the trace (it is Python bookkeeping)
        if m.cfg.init == "rnn":
            m._fused_lstm()

        z = torch.zeros(m.cfg.rnn_layers, 1, H, device=self.device)
        eye = torch.eye(3, device=self.device).expand(S, 3, 3).contiguous()
        ex = (torch.zeros(S * 12, device=self.device), torch.zeros(S, 3, device=self.device), eye, eye,
              torch.zeros(S, 3, device=self.device), z, z)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # TracerWarnings: constants (indices, fused weights) are meant to be baked in
            fn = torch.jit.trace(_OnlineStep(m, self.sensors), ex, check_trace=False)
        self._traced = (key, fn)
        return fn

    @torch.no_grad()  # not inference_mode: the axis-angle (autograd) path needs grad mode inside refine
    def step(self, frame: SensorFrame) -> PoseFrame:
        """One frame: LSTM state carried over, N LGD updates on this frame (offsets from
        :meth:`set_offsets`, identity with a warning if never set). With the 6D pose the updates
        use the closed-form gradient (:mod:`~wearpose.estimators.empose.fastgrad`) in a traced
        function (:meth:`_online_fn`; the first call traces it, ~1 s). With the refinement on
        (``config.refine_steps > 0``) a frame over the gate is refined after the updates
        (:meth:`_refine`; extras ``rec_loss_learned`` and ``refined`` as in :meth:`estimate`).
        With the shape fit on (``config.shape_fit_frames = n > 0``): the first ``n`` frames with
        every sensor valid are kept, and at the n-th the shape is fitted to them once
        (:meth:`_online_shape`; that frame costs the fit, see docs/empose.md); from then on every
        frame returns the fitted shape and is scored with it, before it the learned shape
        (extras ``shape_fitted`` bool, ``rec_loss_learned``). With the refinement's prior on the
        recording (``refine_centre="recording"``, ``refine_centre_frames = n > 0``): the turn is
        measured on the first n valid frames (and every k-th after, ``refine_centre_every``) and
        used from the n-th on (:meth:`_online_turn`; extras ``centre_turned`` bool, and
        ``centre_measured`` bool: this frame added its solve), as :meth:`estimate` does."""
        if self._offsets is None:
            self._refuse_online_centre()
            self._offsets = self._offsets_from(None)
        (p, R), v = self._input(frame)
        if self.model.training:
            self.model.eval()
        dev = self.device
        if self._offsets[0].device != dev:
            self._offsets = (self._offsets[0].to(dev), self._offsets[1].to(dev))
        p, R = p.to(dev), R.to(dev)
        x = sensor_features(p, R)
        offR, offt = self._offsets
        fn = self._online_fn()
        if fn is not None:
            if self._state is None:
                z = torch.zeros(self.model.cfg.rnn_layers, 1, self.model.cfg.hidden, device=dev)
                self._state = (z, z)
            # inference_mode, not only no_grad: the traced ops then keep no autograd metadata (view
            # and version tracking), about a fifth of the step's CPU time (docs/empose.md); the
            # outputs are inference tensors, read but never changed in place below.
            with torch.inference_mode():
                rot, b, rec, h, c = fn(x, p, R, offR, offt, *self._state)
            self._state = (h, c)
        else:
            omega0, self._state = self.model.initial(x[None, None], self._state)
            last = self.model.refine(omega0[0], x[None], p[None], R[None], offR[None], offt[None], self.sensors,
                                     train=False)[-1]
            rot, b, rec = last["local_rot"][0].detach(), last["betas"][0].detach(), last["rec"][0].detach()
        extras: dict[str, Any] = {"frame": "em_source", "rec_loss": float(rec)}
        learned_rec = rec
        if self.config.shape_fit_frames > 0:
            b, rec = self._online_shape(rot, b, rec, p, R, bool(v.all()))
            extras.update(rec_loss=float(rec), rec_loss_learned=float(learned_rec), shape_fitted=self._shape is not None)
        if self.config.refine_steps > 0 and self.config.refine_centre == "recording":
            rot, rec = self._online_turn(rot, b, rec, p, R, bool(v.all()))
            extras.update(centre_turned=self._turn is not None, centre_measured=self._turn_measured)
        if self.config.refine_steps > 0:
            ref = self._refine(rot[None], b[None], rec.reshape(1), p[None], R[None], offR, offt)
            rot = ref.local_rot[0]
            extras.update(rec_loss=float(ref.rec[0]), rec_loss_learned=float(learned_rec), refined=bool(ref.gated[0]))
        return PoseFrame(rot.cpu(), b.cpu(), None, bool(v.all()), frame.timestamp, extras=extras)

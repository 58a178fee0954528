"""LSL outlet of poses: labs record poses beside their other streams (LabRecorder, XDF).

One outlet per subject, created at its first pose: name ``NAME-SUBJECT`` (``--lsl-out-name``,
default ``wearpose-poses``), type ``MoCap``, float32, ``nominal_srate`` = the rate the subject is
estimated at (stream rate / stride). Channels (``desc/channels/channel`` label, unit, type):

- ``JOINT:qw qx qy qz`` per SMPL joint (24 x 4): local joint rotation, unit quaternion (w first),
  type ``Orientation``, in wearpose's frame (Y up; SMPL's joint frames);
- ``root:px py pz``: root translation, m, type ``Position`` (NaN when the method gives none);
- ``JOINT:sigma`` per joint: the method's per-joint uncertainty, type ``Uncertainty``, unit as
  the method defines it (NaN when it gives none);
- ``pose:valid`` (1 / 0) and ``pose:seq`` (the frame's sequence number, exact below 2^24).

Each sample is time-stamped with ``pylsl.local_clock()`` when the pose is sent (the time it
existed on this machine; LSL's clock synchronisation then aligns it with the other streams).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from wearpose.body.skeleton import JOINT_NAMES
from wearpose.geometry import matrix_to_quat

#: Channel labels of a pose sample, in order.
LABELS: tuple[str, ...] = tuple(f"{j}:{c}" for j in JOINT_NAMES for c in ("qw", "qx", "qy", "qz")) + \
    ("root:px", "root:py", "root:pz") + tuple(f"{j}:sigma" for j in JOINT_NAMES) + ("pose:valid", "pose:seq")


def pose_sample(p: Any) -> list[float]:
    """One pose as an LSL sample in :data:`LABELS` order."""
    q = matrix_to_quat(torch.as_tensor(np.asarray(p.local_rot, np.float64))).numpy().reshape(-1)
    trans = np.full(3, np.nan) if p.trans is None else np.asarray(p.trans, np.float64)
    unc = np.full(len(JOINT_NAMES), np.nan) if p.uncertainty is None else np.asarray(p.uncertainty, np.float64)
    return [*q.tolist(), *trans.tolist(), *unc.tolist(), float(bool(p.valid)), float(p.seq)]


class LslPoseOutput:
    """Pushes every subject's poses to its own LSL outlet (module doc)."""

    name = "lsl"

    def __init__(self, name: str = "wearpose-poses", source_id: str = "wearpose") -> None:
        self.stream_name, self.source_id = name, source_id
        self.outlets: dict[int, Any] = {}
        self.sent: dict[int, int] = {}

    def _outlet(self, subject: int, rate: float) -> Any:
        import pylsl  # start-up: pylsl loads liblsl, which reads LSLAPICFG (--lsl-loopback) once

        info = pylsl.StreamInfo(f"{self.stream_name}-{subject}", "MoCap", len(LABELS), float(rate), "float32",
                                f"{self.source_id}-{subject}")
        ch = info.desc().append_child("channels")
        for label in LABELS:
            kind = label.split(":")[1]
            e = ch.append_child("channel")
            e.append_child_value("label", label)
            if kind.startswith("q"):
                e.append_child_value("unit", "quaternion")
                e.append_child_value("type", "Orientation")
            elif kind.startswith("p") and label.startswith("root"):
                e.append_child_value("unit", "m")
                e.append_child_value("type", "Position")
            elif kind == "sigma":
                e.append_child_value("unit", "method-defined")
                e.append_child_value("type", "Uncertainty")
            else:
                e.append_child_value("unit", "")
                e.append_child_value("type", "Misc")
        info.desc().append_child_value("frame", "wearpose: right-handed, Y up; SMPL local joint rotations")
        return pylsl.StreamOutlet(info)

    def pose(self, p: Any, rate: float) -> None:
        import pylsl  # start-up: pylsl loads liblsl, which reads LSLAPICFG (--lsl-loopback) once

        out = self.outlets.get(p.subject)
        if out is None:
            out = self.outlets[p.subject] = self._outlet(p.subject, rate)
        out.push_sample(pose_sample(p), pylsl.local_clock())
        self.sent[p.subject] = self.sent.get(p.subject, 0) + 1

    def stats(self) -> dict[str, Any]:
        return {"output": "lsl", "streams": {f"{self.stream_name}-{k}": n for k, n in self.sent.items()}}

    def close(self) -> None:
        self.outlets.clear()

"""VMC (Virtual Motion Capture) protocol output: every pose as one OSC bundle over UDP.

Per pose (the performer side of the VMC protocol, https://protocol.vmc.info): ``/VMC/Ext/OK 1``
(an avatar is loaded), ``/VMC/Ext/T`` (time, s), ``/VMC/Ext/Root/Pos "root" px py pz qx qy qz qw``
and, per Unity humanoid bone (``HumanBodyBones`` names), ``/VMC/Ext/Bone/Pos NAME px py pz qx qy
qz qw``: the bone's local position (m) and local rotation relative to its parent bone.

Frames: SMPL's local joint rotations are relative to a T-pose whose joint axes are aligned with
the world, as a normalised Unity humanoid's bones are (identity local rotations = T-pose), so a
joint's rotation maps to its bone's by the change of handedness only
(:func:`wearpose.geometry.to_unity_rotation`, ``x -> -x``; Unity's quaternion order x y z w).
The root's translation goes in ``Root/Pos`` (Unity frame, m; zero when the method gives none),
its rotation in the ``Hips`` bone; bone positions are the body model's rest offsets from the
parent joint. SMPL's hand joints (22, 23) have no humanoid bone and are not sent.
"""

from __future__ import annotations

import socket
import struct
from typing import Any

import numpy as np
import torch
from pythonosc.osc_message_builder import OscMessageBuilder

from wearpose.body import BodyModel
from wearpose.body.skeleton import PARENTS
from wearpose.geometry import to_unity_points, to_unity_quat

DEFAULT_PORT = 39539  # the VMC protocol's default receiver (marionette) port
#: Unity HumanBodyBones name of each SMPL joint (None: not sent).
UNITY_BONES: tuple[str | None, ...] = (
    "Hips", "LeftUpperLeg", "RightUpperLeg", "Spine", "LeftLowerLeg", "RightLowerLeg", "Chest",
    "LeftFoot", "RightFoot", "UpperChest", "LeftToes", "RightToes", "Neck", "LeftShoulder", "RightShoulder",
    "Head", "LeftUpperArm", "RightUpperArm", "LeftLowerArm", "RightLowerArm", "LeftHand", "RightHand", None, None,
)


def _message(address: str, args: list[Any]) -> bytes:
    b = OscMessageBuilder(address)
    for a in args:
        b.add_arg(a, "s" if isinstance(a, str) else "i" if isinstance(a, int) else "f")
    return b.build().dgram


def vmc_bundle(local_rot: Any, trans: Any, t: float, offsets: np.ndarray) -> bytes:
    """One pose as a VMC OSC bundle (time tag "immediately").

    Args:
        local_rot: ``(24, 3, 3)`` SMPL local joint rotations (wearpose frame).
        trans: ``(3,)`` root translation m, or None.
        t: the pose's time stamp, s (``/VMC/Ext/T``).
        offsets: ``(24, 3)`` rest offset of each joint from its parent, m (wearpose frame; joint 0:
            the pelvis in the rest pose).
    """
    R = torch.as_tensor(np.asarray(local_rot, np.float64))
    q = to_unity_quat(R).numpy()  # (24, 4) x y z w
    pos = to_unity_points(torch.as_tensor(offsets, dtype=torch.float64)).numpy()
    root = np.zeros(3) if trans is None else to_unity_points(torch.as_tensor(np.asarray(trans, np.float64))).numpy()
    msgs = [_message("/VMC/Ext/OK", [1]), _message("/VMC/Ext/T", [float(t)]),
            _message("/VMC/Ext/Root/Pos", ["root", *map(float, root), 0.0, 0.0, 0.0, 1.0])]
    for j, name in enumerate(UNITY_BONES):
        if name is not None:
            msgs.append(_message("/VMC/Ext/Bone/Pos", [name, *map(float, pos[j]), *map(float, q[j])]))
    parts = [b"#bundle\x00", struct.pack(">II", 0, 1)]  # time tag 1 = immediately (OSC 1.0)
    for m in msgs:
        parts += [struct.pack(">i", len(m)), m]
    return b"".join(parts)


def rest_offsets(betas: Any = None) -> np.ndarray:
    """``(24, 3)`` m: each joint's rest position minus its parent's (the pelvis: its own)."""
    J = BodyModel().rest_joints(None if betas is None else torch.as_tensor(betas, dtype=torch.float32)).double().numpy()
    off = J.copy()
    for j, p in enumerate(PARENTS):
        if p >= 0:
            off[j] = J[j] - J[p]
    return off


class VmcOutput:
    """Sends subject ``subject``'s poses to a VMC receiver at ``host:port`` (UDP).

    Args:
        host, port: the receiver (VSeeFace / Warudo / VNyan / Unity's VMC receiver; default 127.0.0.1:39539).
        subject: which subject drives the avatar (VMC carries one).
    """

    name = "vmc"

    def __init__(self, host: str = "127.0.0.1", port: int = DEFAULT_PORT, subject: int = 0) -> None:
        self.host, self.port, self.subject = host, port, subject
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setblocking(False)
        self.offsets = rest_offsets()
        self.sent = self.dropped = self.errors = 0

    def pose(self, p: Any, rate: float) -> None:
        if p.subject != self.subject:
            return
        try:
            self.sock.sendto(vmc_bundle(p.local_rot, p.trans, p.timestamp, self.offsets), (self.host, self.port))
            self.sent += 1
        except BlockingIOError:
            self.dropped += 1  # the socket's send buffer is full: never wait for a receiver
        except OSError:
            self.errors += 1  # e.g. ICMP port unreachable from an earlier datagram: nobody listening yet

    def stats(self) -> dict[str, Any]:
        return {"output": "vmc", "target": f"udp://{self.host}:{self.port}", "subject": self.subject,
                "sent": self.sent, "dropped": self.dropped, "errors": self.errors}

    def close(self) -> None:
        self.sock.close()

"""Pose outputs (issue 26): VMC over OSC to a python-osc receiver, and an LSL outlet of poses;
all traffic on 127.0.0.1."""

from __future__ import annotations

import asyncio
import math
import threading
import time

import numpy as np
import pytest
import torch

from tests.stream.conftest import EchoEstimator
from wearpose.geometry import rotation_y
from wearpose.stream import Faults, StreamServer, replay
from wearpose.stream.outputs.lsl import LABELS, LslPoseOutput
from wearpose.stream.outputs.vmc import UNITY_BONES, VmcOutput
from wearpose.stream.packets import PosePacket

H = math.sqrt(0.5)


class VmcReceiver:
    """A python-osc UDP server on 127.0.0.1 keeping every VMC message (per bundle: its bones)."""

    def __init__(self) -> None:
        from pythonosc.dispatcher import Dispatcher
        from pythonosc.osc_server import BlockingOSCUDPServer

        self.frames: list[dict[str, tuple[float, ...]]] = []
        self.roots: list[tuple[float, ...]] = []
        self.times: list[float] = []
        d = Dispatcher()
        d.map("/VMC/Ext/Bone/Pos", self._bone)
        d.map("/VMC/Ext/Root/Pos", self._root)
        d.map("/VMC/Ext/T", lambda addr, t: self.times.append(t))
        self.server = BlockingOSCUDPServer(("127.0.0.1", 0), d)
        self.port = self.server.server_address[1]
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)
        self.thread.start()

    def _root(self, addr: str, name: str, *v: float) -> None:
        self.roots.append(v)
        self.frames.append({})

    def _bone(self, addr: str, name: str, *v: float) -> None:
        self.frames[-1][name] = v

    def wait(self, n: int, timeout: float = 10.0) -> None:
        t = time.time() + timeout
        while len(self.frames) < n and time.time() < t:
            time.sleep(0.02)
        time.sleep(0.05)

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()


def _pose(local_rot: np.ndarray, seq: int = 0, trans=None, unc=None) -> PosePacket:
    return PosePacket(0, seq, seq / 60.0, True, local_rot.astype(np.float32), np.zeros(10, np.float32),
                      trans, unc)


def test_vmc_left_elbow_bent_arrives_as_hand_computed_unity_quaternions() -> None:
    rx = VmcReceiver()
    out = VmcOutput("127.0.0.1", rx.port)
    try:
        R = np.tile(np.eye(3), (24, 1, 1))
        # T-pose with the left elbow bent 90 degrees: the left forearm (along +X) turned to point
        # forward (+Z), R_y(-90 deg) in wearpose's frame.
        R[18] = rotation_y(torch.tensor(-math.pi / 2, dtype=torch.float64)).numpy()
        out.pose(_pose(R, trans=np.array([0.5, 0.9, -0.2], np.float32)), 60.0)
        rx.wait(1)
    finally:
        out.close()
        rx.close()
    assert len(rx.frames) == 1
    bones = rx.frames[0]
    assert set(bones) == {b for b in UNITY_BONES if b is not None} and len(bones) == 22
    # Unity (left-handed, left arm along -X): Quaternion.Euler(0, 90, 0) = (x, y, z, w) = (0, .7071, 0, .7071)
    assert np.allclose(bones["LeftLowerArm"][3:], (0.0, H, 0.0, H), atol=1e-6)
    for name, v in bones.items():
        if name != "LeftLowerArm":
            assert np.allclose(v[3:], (0, 0, 0, 1), atol=1e-6), name
    # the left upper arm's offset from the collar points to the subject's left: -X in Unity
    assert bones["LeftUpperArm"][0] < -0.05 and bones["RightUpperArm"][0] > 0.05
    assert np.allclose(rx.roots[0][:3], (-0.5, 0.9, -0.2), atol=1e-6)  # x negated
    assert np.allclose(rx.roots[0][3:], (0, 0, 0, 1))


@pytest.mark.budget(20)  # ~3 s: 1 s of frames at 60 Hz through the server
def test_vmc_receiver_gets_every_pose_through_the_server(recording) -> None:
    rx = VmcReceiver()
    out = VmcOutput("127.0.0.1", rx.port)

    async def run() -> dict:
        async with StreamServer(lambda: EchoEstimator(), port=0, warmup=0) as srv:
            srv.outputs.append(out)
            res = await replay(recording, srv.url, faults=Faults(seed=0))
            return {**res, "stats": srv.stats()}

    try:
        res = asyncio.run(run())
        rx.wait(res["poses_received"])
    finally:
        out.close()
        rx.close()
    assert res["frames_lost"] == 0 and res["poses_received"] == res["frames_sent"] > 0
    assert len(rx.frames) == res["frames_sent"] == out.sent, "one VMC bundle per pose"
    assert all(len(f) == 22 for f in rx.frames)
    assert res["stats"]["outputs"][0]["sent"] == res["frames_sent"]


@pytest.mark.budget(20)
def test_lsl_outlet_of_poses_reads_back() -> None:
    import pylsl

    out = LslPoseOutput("wearpose-test-poses")
    g = torch.Generator().manual_seed(0)
    from wearpose.geometry import axis_angle_to_matrix

    R = axis_angle_to_matrix(0.5 * torch.randn(5, 24, 3, generator=g, dtype=torch.float64)).numpy()
    unc = np.linspace(0.1, 2.4, 24).astype(np.float32)
    out.pose(_pose(R[0], 0, np.array([1.0, 2.0, 3.0], np.float32), unc), 60.0)  # creates the outlet
    found = pylsl.resolve_byprop("name", "wearpose-test-poses-0", 1, 10.0)
    assert found, "the pose outlet is visible on this machine"
    inlet = pylsl.StreamInlet(found[0])
    info = inlet.info(5.0)
    assert info.channel_count() == len(LABELS) == 24 * 4 + 3 + 24 + 2
    from tests.stream.conftest import LSL_TEST_SESSION

    assert info.session_id() == LSL_TEST_SESSION, "liblsl read the loopback configuration (LSLAPICFG)"
    labels, c = [], info.desc().child("channels").child("channel")
    while not c.empty():
        labels.append(c.child_value("label"))
        c = c.next_sibling()
    assert tuple(labels) == LABELS
    inlet.open_stream(5.0)
    time.sleep(0.3)
    # Even frames carry a root translation and a per-joint uncertainty, odd ones neither.
    roots = {k: np.array([0.1 * k, 0.9, -0.2 * k], np.float32) for k in (2, 4)}
    for k in range(1, 5):
        out.pose(_pose(R[k], k, roots.get(k), unc * k if k in roots else None), 60.0)
    rows, t = [], time.time() + 5
    while len(rows) < 4 and time.time() < t:
        chunk, _ = inlet.pull_chunk(timeout=0.5)
        rows += chunk
    out.close()
    assert len(rows) == 4
    from wearpose.geometry import quat_to_matrix

    for k, row in zip(range(1, 5), rows):
        q = torch.tensor(row[:96], dtype=torch.float64).reshape(24, 4)
        assert np.allclose(quat_to_matrix(q).numpy(), R[k], atol=1e-5)
        if k in roots:
            assert np.allclose(row[96:99], roots[k]) and np.allclose(row[99:123], unc * k, rtol=1e-6)
        else:
            assert np.isnan(row[96:99]).all() and np.isnan(row[99:123]).all()  # no translation / uncertainty
        assert row[123] == 1.0 and row[124] == k

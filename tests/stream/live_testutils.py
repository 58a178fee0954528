"""Simulated recordings, the in-process reference and one serve-and-emulate run for the live
input tests (tests/stream/test_live_*.py) and benchmarks/live_inputs.py."""

from __future__ import annotations

import asyncio
import functools
import socket
import warnings
from typing import Any, Callable

import numpy as np
import torch

from wearpose.recording import Recording


@functools.lru_cache(maxsize=None)
def simulated(kit: str, fps: float, seconds: float, noise: str = "default", seed: int = 1) -> Recording:
    """``seconds`` of smooth synthetic motion worn with ``kit`` at ``fps`` (cached: do not modify)."""
    from tests.sensors.sensor_testutils import smooth_motion
    from wearpose.body import BodyModel
    from wearpose.sensors import simulate

    m = smooth_motion(T=int(round(seconds * fps)), fps=fps, seed=seed, dtype=torch.float32)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = simulate(m, kit, BodyModel(), seed=seed + 1, noise=noise, rate=fps,
                       offsets="random" if kit.startswith("em") else None)
    return Recording.from_simulation(res, m, source_pose=False)


def reference_poses(factory: Callable[[], Any], recording: Recording) -> np.ndarray:
    """The same model stepping through the same recording in-process: local rotations ``(T, 24, 3, 3)``."""
    from wearpose.estimators.base import iter_frames

    est = factory()
    if recording.subject.get("offsets") and hasattr(est, "set_offsets") and hasattr(est, "_offsets_from"):
        est.set_offsets(*est._offsets_from(recording))
    est.reset()
    return np.stack([est.step(f).local_rot.numpy() for f in iter_frames(recording)])


class Collect:
    """A pose sink keeping every pose of the run (by sequence number)."""

    name = "collect"

    def __init__(self) -> None:
        self.poses: dict[int, Any] = {}
        self.duplicates = 0

    def pose(self, p: Any, rate: float) -> None:
        self.duplicates += int(p.seq in self.poses)
        self.poses[p.seq] = p

    def stats(self) -> dict[str, Any]:
        return {"output": self.name, "poses": len(self.poses)}

    def close(self) -> None:
        pass


async def serve_and_emulate(name: str, recording: Recording, factory: Callable[[], Any], *, faults: Any = None,
                            speed: float = 1.0, duration: float | None = None, warmup: int = 5,
                            max_lag_s: float | None = None) -> tuple[Collect, dict[str, Any], dict[str, Any]]:
    """A server on 127.0.0.1 with input ``name`` fed by its emulator playing ``recording``:
    (collected poses, the subject's final server stats incl. ``malformed_total``, emulator result)."""
    from wearpose.stream import StreamServer
    from wearpose.stream.live import InputBridge

    from wearpose.stream.security import Limits

    # The overload policy (frames older than 0.5 s shed) is off: these runs measure the inputs on
    # a loaded test machine, where the estimator may fall behind a 2x-speed emulator; every
    # frame must then still be estimated, late.
    async with StreamServer(factory, "127.0.0.1", 0, warmup=warmup, stride=1,
                            limits=Limits(max_lag_s=max_lag_s)) as srv:
        sink = Collect()
        srv.outputs.append(sink)
        src, emulate = _input_and_emulator(name, recording)
        bridge = InputBridge(srv, src, 0, dict(recording.subject or {}))
        if name in ("lsl", "ximu3"):  # the inlet resolves the outlet / connects to the devices: start both together
            emu_task = asyncio.create_task(emulate(src, faults, speed, duration))
            await bridge.start()
            emu = await emu_task
        else:
            await bridge.start()
            emu = await emulate(src, faults, speed, duration)
        await asyncio.sleep(0.3)  # the last datagrams / samples
        final = await bridge.stop()
        final = {**final, "malformed_total": srv.malformed, "input": bridge.stats()}
    return sink, final, emu


def _input_and_emulator(name: str, rec: Recording) -> tuple[Any, Callable[..., Any]]:
    if name == "mvn":
        from wearpose.stream.inputs.mvn import MvnInput, emulate_mvn

        src = MvnInput("127.0.0.1", 0, segments=rec.names, rate=_rate(rec))
        return src, lambda s, f, sp, d: emulate_mvn(rec, "127.0.0.1", s.port, faults=f, speed=sp, duration=d)
    if name == "osc":
        from wearpose.stream.inputs.osc import OscInput, emulate_osc

        port = _free_ports(len(rec.names), socket.SOCK_DGRAM)
        src = OscInput("ngimu", dict(zip(rec.names, port)), _rate(rec))
        return src, lambda s, f, sp, d: emulate_osc(rec, "ngimu", "127.0.0.1", ports=s.ports, faults=f, speed=sp,
                                                    duration=d)
    if name == "osc-generic":
        from wearpose.stream.inputs.osc import OscInput, emulate_osc

        port = _free_ports(1, socket.SOCK_DGRAM)[0]
        src = OscInput("generic", list(rec.names), _rate(rec), port=port)
        return src, lambda s, f, sp, d: emulate_osc(rec, "generic", "127.0.0.1", port, faults=f, speed=sp, duration=d)
    if name == "ximu3":  # TCP: the emulated devices listen on 127.0.0.1, the input connects (nothing else listens)
        from wearpose.stream.inputs.ximu3 import Ximu3Input, emulate_ximu3

        ports = dict(zip(rec.names, _free_ports(len(rec.names), socket.SOCK_STREAM)))
        src = Ximu3Input(ports, _rate(rec), "127.0.0.1", "tcp", timeout=30.0)
        return src, lambda s, f, sp, d: emulate_ximu3(rec, "127.0.0.1", ports=ports, transport="tcp", faults=f, speed=sp,
                                                      duration=d, connect_timeout=30.0)
    if name == "lsl":
        import uuid

        from wearpose.stream.inputs.lsl import LslInput, emulate_lsl

        stream = f"wearpose-test-{uuid.uuid4().hex[:8]}"
        src = LslInput(stream, timeout=20.0)
        conv = {"position_unit": "cm"} if "em6dof" in rec.kinds else {"gyro_unit": "deg/s", "acc_unit": "g"}
        return src, lambda s, f, sp, d: emulate_lsl(rec, stream, faults=f, speed=sp, duration=d, **conv)
    raise ValueError(name)


def _rate(rec: Recording) -> float:
    return float(round(rec.sensors[0].info.rate, 6))


def _free_ports(n: int, kind: int) -> list[int]:
    """``n`` distinct free 127.0.0.1 ports of socket ``kind`` (SOCK_DGRAM or SOCK_STREAM), all
    held open together so that none is handed out twice."""
    socks = [socket.socket(socket.AF_INET, kind) for _ in range(n)]
    for s in socks:
        s.bind(("127.0.0.1", 0))
    ports = [s.getsockname()[1] for s in socks]
    for s in socks:
        s.close()
    return ports


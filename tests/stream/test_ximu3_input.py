"""x-IMU3 live input (wearpose.stream.inputs.ximu3) at the wire: the emulator's messages as the
official ximu3 package decodes them, what is malformed, samples and clocks. TCP on 127.0.0.1 only:
the emulated device listens, the input connects (ximu3's UDP connection would bind all interfaces)."""

from __future__ import annotations

import asyncio
import struct
from typing import Any

import numpy as np
import pytest

pytest.importorskip("ximu3")

from wearpose.errors import ConfigError  # noqa: E402
from wearpose.stream.inputs import make_input  # noqa: E402
from wearpose.stream.inputs.ximu3 import END, ESC, Ximu3Input, encode_message, malformed_message  # noqa: E402

Q = [0.5, 0.5, -0.5, 0.5]  # a unit quaternion (w, x, y, z)


async def _device_run(payloads: list[list[bytes]], settle: float = 0.4) -> tuple[Ximu3Input, list[Any], list[Any]]:
    """One input with ``len(payloads)`` devices (names d0, d1...), each a TCP server on 127.0.0.1
    that writes its payload chunks once the input is connected; (input, frames, malformed)."""
    servers, writers = [], []
    connected = [asyncio.get_running_loop().create_future() for _ in payloads]

    for i in range(len(payloads)):
        def on_client(reader: Any, writer: asyncio.StreamWriter, i: int = i) -> None:
            writers.append(writer)
            connected[i].set_result(writer)
        servers.append(await asyncio.start_server(on_client, "127.0.0.1", 0))
    ports = {f"d{i}": s.sockets[0].getsockname()[1] for i, s in enumerate(servers)}
    src = Ximu3Input(ports, 50.0, "127.0.0.1", "tcp", timeout=5.0)
    frames: list[Any] = []
    bad: list[Any] = []
    src.attach(frames.append, bad.append)
    await src.open()
    for fut, chunks in zip(connected, payloads):
        w = await asyncio.wait_for(fut, 5.0)
        for c in chunks:
            w.write(c)
        await w.drain()
    await asyncio.sleep(settle)
    await src.close()
    for w in writers:
        w.close()
    for s in servers:
        s.close()
    return src, frames, bad


def _sample(ts: int, gyro=(1.0, -2.0, 3.0), acc=(0.0, 0.0, 1.0), q=Q, fmt: str = "binary") -> list[bytes]:
    return [encode_message("I", ts, [*gyro, *acc], fmt), encode_message("Q", ts, list(q), fmt)]


def test_binary_byte_stuffing_decoded_by_ximu3() -> None:
    # A timestamp and values whose little-endian bytes hold END (0x0A) and ESC (0xDB): the
    # encoder escapes them and ximu3 decodes the original values.
    ts = 0x0A0ADBDB0A
    gyro = (struct.unpack("<f", bytes([0x0A, 0xDB, 0x0A, 0x3F]))[0], 0.25, -1.5)
    msg = encode_message("I", ts, [*gyro, 0.0, 0.0, 1.0])
    assert msg.count(bytes([END])) == 1 and msg.endswith(bytes([END])) and ESC in msg
    src, frames, bad = asyncio.run(_device_run([_sample(ts, gyro=gyro) + _sample(ts + 20000, gyro=gyro)]))
    assert bad == [] and src.counts["receive_errors"] == 0
    assert len(frames) == 2 and [f.seq for f in frames] == [0, 1]
    np.testing.assert_allclose(frames[0].channels["angular_velocity"][0], np.float32(gyro), rtol=0, atol=0)
    w, x, y, z = Q  # R_WS of the quaternion, first column = R @ e_x
    np.testing.assert_allclose(frames[0].channels["orientation"][0][:, 0],
                               [1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)], atol=1e-6)
    assert frames[0].timestamp == pytest.approx(ts / 1e6)


def test_ascii_messages_four_decimals() -> None:
    assert encode_message("Q", 1000000, [1, 0, 0, 0], "ascii") == b"Q,1000000,1.0000,0.0000,0.0000,0.0000\r\n"
    src, frames, bad = asyncio.run(_device_run([_sample(1000000, gyro=(0.12344, 0, 0), fmt="ascii")]))
    assert bad == [] and len(frames) == 1
    assert frames[0].channels["angular_velocity"][0, 0] == pytest.approx(0.1234, abs=1e-6)


@pytest.mark.parametrize("kind", [0, 1, 2, 3])
def test_each_malformed_message_counted_once(kind: int) -> None:
    # Between two good samples: the bad message is counted once and costs no sample.
    chunks = _sample(0) + [malformed_message(kind, 10000, Q, "binary")] + _sample(20000)
    src, frames, bad = asyncio.run(_device_run([chunks]))
    assert len(bad) == 1 and src.counts["malformed"] == 1, (kind, [str(b) for b in bad])
    assert [f.seq for f in frames] == [0, 1] and all(f.valid.all() for f in frames)


def test_a_sample_is_the_pair_and_a_missing_device_is_masked() -> None:
    # d0 sends samples 0..4; d1 sends 0, 1, its quaternion only at 2 (no twin), then 3, 4.
    d0 = [c for k in range(5) for c in _sample(k * 20000)]
    d1 = [c for k in (0, 1) for c in _sample(k * 20000)] + [encode_message("Q", 40000, Q)] + \
        [c for k in (3, 4) for c in _sample(k * 20000)]
    src, frames, bad = asyncio.run(_device_run([d0, d1]))
    assert bad == [] and [f.seq for f in frames] == [0, 1, 2, 3, 4]
    assert [bool(f.valid[1]) for f in frames] == [True, True, False, True, True]
    assert np.isnan(frames[2].channels["orientation"][1]).all()
    assert src.counts["unpaired"] == 1


def test_a_device_on_another_clock_joins_by_arrival() -> None:
    # d1's clock is 1000 s ahead of d0's: not one clock; its first sample joins the newest frame.
    d0 = [c for k in range(4) for c in _sample(k * 20000)]
    src, frames, _ = asyncio.run(_device_run([d0, []]))
    assert len(frames) == 4 and not any(f.valid[1] for f in frames)  # d1 silent: masked (released at close)
    src2 = Ximu3Input({"a": 1, "b": 2}, 50.0)
    src2._loop = None
    got: list[Any] = []
    src2.attach(got.append, lambda e: None)
    for k in range(3):
        for j, off in ((0, 0), (1, 1000_000_000)):
            src2._inertial(j, off + k * 20000, [0, 0, 0, 0, 0, 1])
            src2._quaternion(j, off + k * 20000, Q)
    assert [f.seq for f in got] == [0, 1, 2] and all(f.valid.all() for f in got)


def test_make_input_needs_devices_and_rate() -> None:
    with pytest.raises(ConfigError, match="--ximu3-sensor NAME=PORT"):
        make_input("ximu3", rate=50.0)
    with pytest.raises(ConfigError, match="--device-rate"):
        make_input("ximu3", ximu3_sensors={"pelvis": 7000})
    with pytest.raises(ConfigError, match="transport"):
        make_input("ximu3", rate=50.0, ximu3_sensors={"pelvis": 7000}, ximu3_transport="serial")

"""``wearpose view-live`` as a process: it stops on SIGTERM / Ctrl-C, and by itself (saying
why) when its server goes away -- it used to need SIGKILL once the server had stopped."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SERVER = """
import asyncio, signal, sys
from tests.stream.conftest import EchoEstimator
from wearpose.stream import StreamServer

async def main():
    stop = asyncio.Event()
    asyncio.get_running_loop().add_signal_handler(signal.SIGTERM, stop.set)
    async with StreamServer(EchoEstimator, port=0) as srv:
        print(srv.url, flush=True)
        await stop.wait()

asyncio.run(main())
"""


def _env() -> dict[str, str]:
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    env.pop("WEARPOSE_DEBUG", None)
    return env


def _line(proc: subprocess.Popen, startswith: str, timeout: float) -> str:
    """The first stdout line starting with ``startswith`` (the process is killed on timeout)."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        line = proc.stdout.readline()
        if line.startswith(startswith):
            return line.strip()
        if not line and proc.poll() is not None:
            break
    proc.kill()
    pytest.fail(f"no {startswith!r} line within {timeout} s (exit {proc.poll()})")


def _start(tmp_path: Path) -> tuple[subprocess.Popen, subprocess.Popen]:
    server = subprocess.Popen([sys.executable, "-c", SERVER], cwd=ROOT, env=_env(), stdout=subprocess.PIPE, text=True)
    url = _line(server, "ws://", 60)
    viewer = subprocess.Popen([sys.executable, "-m", "wearpose.cli", "view-live", "--url", url, "--port", "0"],
                              cwd=tmp_path, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    _line(viewer, "subscribed to ws://", 60)
    return server, viewer


def _wait(proc: subprocess.Popen, timeout: float) -> int | None:
    try:
        return proc.wait(timeout)
    except subprocess.TimeoutExpired:
        proc.kill()  # never leave it behind, even when the test fails
        proc.wait(10)
        return None


@pytest.mark.budget(30)  # two processes, a browser-less viewer and a signal: 14 s measured
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_view_live_exits_on_a_signal_while_connected(tmp_path: Path, sig: int) -> None:
    server, viewer = _start(tmp_path)
    try:
        viewer.send_signal(sig)
        assert _wait(viewer, 10) == 0, viewer.stderr.read()
    finally:
        server.terminate()
        _wait(server, 10)


@pytest.mark.budget(30)  # 14 s measured
def test_view_live_stops_by_itself_when_its_server_stops(tmp_path: Path) -> None:
    server, viewer = _start(tmp_path)
    server.terminate()
    assert _wait(server, 15) is not None
    code = _wait(viewer, 10)
    out = viewer.stdout.read()
    assert code == 0 and "closed the connection; viewer stopped" in out, (code, out, viewer.stderr.read())

"""``wearpose serve`` as a user runs it: its own process, stopped with SIGINT (clean shutdown)."""

from __future__ import annotations

import asyncio
import json
import signal
import subprocess
import sys

from tests.stream.conftest import tiny_recording
from wearpose.stream import Faults, replay


def test_serve_then_clean_sigint_shutdown() -> None:
    server = subprocess.Popen([sys.executable, "-m", "wearpose.cli", "serve", "--model", "null", "--port", "0",
                               "--log-level", "ERROR", "--json"], stdout=subprocess.PIPE, text=True)
    try:
        line = server.stdout.readline()
        assert " on ws://" in line, line
        url = line.strip().split(" on ")[-1]
        r = asyncio.run(replay(tiny_recording(60), url, realtime=False, faults=Faults(malformed=0.1, seed=2)))
        assert r["frames_sent"] == 60 and r["frames_lost"] == 0 and r["injected"]["malformed"] > 0
    finally:
        server.send_signal(signal.SIGINT)
        rest, _ = server.communicate(timeout=60)
    assert server.returncode == 0
    final = json.loads(rest)
    assert final["finished"]["0"]["estimated"] == 60 and final["malformed_total"] == r["injected"]["malformed"]

"""``wearpose serve`` as a user runs it: its own process, stopped with SIGINT (clean shutdown);
its security options checked before anything starts; ``wearpose stream replay`` stopping when
its server does."""

from __future__ import annotations

import asyncio
import json
import signal
import subprocess
import sys
import threading
import time

import pytest
from typer.testing import CliRunner

from tests.stream.conftest import EchoEstimator, tiny_recording
from wearpose.cli.app import app
from wearpose.recording import save_recording
from wearpose.stream import Faults, StreamServer, replay


@pytest.mark.budget(30)  # a CLI process (imports torch) started and stopped: 16-19 s measured
def test_serve_then_clean_sigint_shutdown() -> None:
    server = subprocess.Popen([sys.executable, "-m", "wearpose.cli", "serve", "--model", "null", "--port", "0",
                               "--log-level", "ERROR", "--json"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True)
    try:
        line = server.stdout.readline()
        assert " on ws://" in line, line
        url = line.strip().split(" on ")[-1]
        r = asyncio.run(replay(tiny_recording(60), url, realtime=False, faults=Faults(malformed=0.1, seed=2)))
        assert r["frames_sent"] == 60 and r["frames_lost"] == 0 and r["injected"]["malformed"] > 0
    finally:
        server.send_signal(signal.SIGINT)
        rest, err = server.communicate(timeout=60)
    assert server.returncode == 0
    final = json.loads(rest)
    assert final["finished"]["0"]["estimated"] == 60 and final["malformed_total"] == r["injected"]["malformed"]
    # the generated token, printed at start-up (stderr: stdout is the one line scripts wait for)
    assert "access token (optional on loopback" in err and final["security"]["token_required"] is False


def test_serve_security_options_reach_the_server_and_bad_ones_fail_first(monkeypatch) -> None:  # noqa: ANN001
    import wearpose.stream as stream

    seen: dict = {}

    def fake_run_server(factory, host, port, **kw):  # noqa: ANN001, ANN202
        seen.update(kw, host=host)
        return {"finished": [], "malformed_total": 0}

    monkeypatch.setattr(stream, "run_server", fake_run_server)
    runner = CliRunner()
    res = runner.invoke(app, ["serve", "--model", "null", "--host", "0.0.0.0", "--token", "a-long-enough-token",
                              "--allow-origin", "HTTP://Dash.example:3000/", "--allow-origin", "https://x.example",
                              "--rate-limit", "100", "--max-subscriptions", "4", "--require-token"])
    assert res.exit_code == 0, res.output
    assert seen["token"] == "a-long-enough-token" and seen["require_token"] is True
    assert seen["allow_origins"] == ["http://dash.example:3000", "https://x.example"]
    assert seen["limits"].rate == 100 and seen["limits"].subscriptions == 4
    res = runner.invoke(app, ["serve", "--model", "null"])
    assert res.exit_code == 0 and len(seen["token"]) == 43  # generated
    for args, message in ((["--token", "short"], "--token: expected at least 16 characters"),
                          (["--allow-origin", "evil.example"], "--allow-origin 'evil.example': expected an origin")):
        res = runner.invoke(app, ["serve", "--model", "null", *args])
        assert res.exit_code != 0 and message in str(res.exception), (res.output, res.exception)


def test_stream_replay_exits_with_an_error_when_the_server_stops(tmp_path) -> None:  # noqa: ANN001
    """`wearpose stream replay --duration 25` against a server stopping after 1 s: it exits with
    code 1 and says why within seconds (it used to hang for over 90 s)."""
    path = tmp_path / "rec.npz"
    save_recording(tiny_recording(60), path)
    started, stop = threading.Event(), threading.Event()
    box: dict = {}

    def serve() -> None:
        async def main() -> None:
            async with StreamServer(EchoEstimator, port=0, warmup=0) as srv:
                box["url"] = srv.url
                started.set()
                while not stop.is_set():
                    await asyncio.sleep(0.02)
        asyncio.run(main())

    th = threading.Thread(target=serve, daemon=True)
    th.start()
    assert started.wait(10)
    threading.Timer(1.0, stop.set).start()
    t0 = time.perf_counter()
    res = CliRunner().invoke(app, ["stream", "replay", str(path), "--url", box["url"], "--duration", "25"])
    took = time.perf_counter() - t0
    th.join(10)
    assert res.exit_code == 1 and "stopped early" in res.output and "server stopping" in res.output, res.output
    assert took < 5

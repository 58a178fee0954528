"""`wearpose stream emulate` and `wearpose serve --input/--output`: a user's mistakes give one
clear line and a non-zero exit; a real emulation on loopback reports what it sent."""

from __future__ import annotations

import json
import socket

import numpy as np
import pytest

from tests.cli.test_errors import run_main
from tests.stream.conftest import tiny_recording


def _rec(tmp_path) -> str:
    p = tmp_path / "rec.npz"
    tiny_recording(T=30).save(p)  # EM sensors named a, b, c, d
    return str(p)


def test_emulate_mvn_refuses_sensor_names_that_are_no_segments(tmp_path, capsys, monkeypatch) -> None:
    code, err = run_main(["stream", "emulate", "mvn", _rec(tmp_path), "--port", "9"], capsys, monkeypatch)
    assert code != 0 and "MVN segment 'a'" in err and "pelvis" in err


def test_emulate_unknown_input(tmp_path, capsys, monkeypatch) -> None:
    code, err = run_main(["stream", "emulate", "xsens", _rec(tmp_path)], capsys, monkeypatch)
    assert code == 2 and "lsl, osc, mvn" in err


def test_serve_osc_without_sensors_names_the_option(capsys, monkeypatch) -> None:
    code, err = run_main(["serve", "--model", "null", "--input", "osc", "--device-rate", "60"], capsys, monkeypatch)
    assert code != 0 and "--osc-sensor" in err


@pytest.mark.budget(20)
def test_emulate_osc_generic_sends_every_frame(tmp_path, capsys, monkeypatch) -> None:
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)  # read only after the emulation
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(0.5)
    port = rx.getsockname()[1]
    import sys

    from wearpose.cli import main

    monkeypatch.setattr(sys, "argv", ["wearpose", "stream", "emulate", "osc", _rec(tmp_path), "--osc-profile", "generic",
                                      "--port", str(port), "--speed", "4", "--json"])
    with pytest.raises(SystemExit) as ex:
        main()
    assert ex.value.code in (0, None)
    stdout = capsys.readouterr().out
    out = json.loads(stdout[stdout.index("{"):])
    n = 0
    try:
        while True:
            rx.recv(65536)
            n += 1
    except socket.timeout:
        pass
    rx.close()
    # EM sensors carry no acceleration / gyro: the generic map still sends its three messages per sensor
    assert out["frames_sent"] == 30 and n == 30 * 4 - out["recording_masked_samples"]  # a bundle per valid sample
    assert np.isclose(out["rate_hz"], 60.0)

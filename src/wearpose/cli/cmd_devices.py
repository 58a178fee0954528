"""``wearpose stream emulate INPUT RECORDING``: a loopback device emulator for each live input
of ``wearpose serve --input`` (thin: :func:`wearpose.stream.inputs.emulate_input`)."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any, List, Optional

import typer
from rich.table import Table

from wearpose.cli.app import _emit, console, err_console
from wearpose.cli.cmd_serve import stream_app
from wearpose.cli.cmd_serve import _lsl_loopback
from wearpose.cli.cmd_serve import _ximu3_ports
from wearpose.errors import ConfigError


@stream_app.command("emulate")
def stream_emulate(
    input_name: str = typer.Argument(..., metavar="INPUT", help="lsl, osc, mvn or ximu3: the wire format to "
                                                                         "speak."),
    recording: Path = typer.Argument(..., help="A wearpose recording (.npz) to play at its real rate."),
    host: str = typer.Option("127.0.0.1", help="Where to send (OSC, MVN); loopback by default."),
    port: Optional[int] = typer.Option(None, help="UDP port (MVN: 9763; OSC address profiles: 9000; OSC ngimu: "
                                                  "the first device's port, the next ones +1 unless --osc-sensor)."),
    lsl_stream: str = typer.Option("wearpose-sensors", help="lsl: name of the outlet."),
    lsl_loopback: bool = typer.Option(False, "--lsl-loopback", help="Keep LSL on this machine (as wearpose serve)."),
    osc_profile: str = typer.Option("ngimu", help="osc: the address map (ngimu, generic or a YAML file)."),
    osc_sensor: Optional[List[str]] = typer.Option(None, "--osc-sensor", help="osc ngimu: NAME=PORT per sensor."),
    ximu3_sensor: Optional[List[str]] = typer.Option(None, "--ximu3-sensor", help="ximu3: NAME=PORT per device "
                                                                                  "(default --port + i, from 7000)."),
    ximu3_transport: str = typer.Option("tcp", help="ximu3: tcp (each device listens; start serve after or "
                                                    "before) or udp (sends to the port)."),
    ximu3_format: str = typer.Option("binary", help="ximu3: binary (float32) or ascii (four decimals) messages."),
    speed: float = typer.Option(1.0, help="Playback speed (1 = the recording's real rate)."),
    duration: Optional[float] = typer.Option(None, help="Seconds to play, looping the recording (default: once)."),
    malformed: float = typer.Option(0.0, help="Send a malformed packet after this fraction of frames."),
    dropout: float = typer.Option(0.0, help="Per-sensor, per-frame probability of starting a 1-30 frame dropout."),
    seed: int = typer.Option(0, help="Seed of the injected faults."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as JSON."),
) -> None:
    """Play a recording as a live device (LSL outlet, OSC devices, Xsens MVN streamer, x-IMU3s) on loopback.

    Sensor names must be those the input reads: MVN segments (pelvis, head, left_forearm, ...)
    for mvn; any names for lsl, osc and ximu3. Start `wearpose serve --input INPUT` first (lsl,
    ximu3 over tcp: either order).

    Example: wearpose stream emulate mvn recs/imu6.npz --malformed 0.01 --dropout 0.001
    """
    from wearpose.recording import load_recording  # start-up: wearpose.recording loads torch, +1.7 s to wearpose --help
    from wearpose.stream.inputs import INPUTS, emulate_input  # start-up: wearpose.stream.inputs loads torch, +2.0 s to wearpose --help
    from wearpose.stream.inputs.osc import parse_sensor_ports  # start-up: wearpose.stream.inputs.osc loads torch, +1.9 s to wearpose --help
    from wearpose.stream.replay import Faults  # start-up: wearpose.stream.replay loads torch, +1.8 s to wearpose --help

    if input_name not in INPUTS:
        raise typer.BadParameter(f"expected one of {', '.join(INPUTS)}, got {input_name!r}", param_hint="INPUT")
    if lsl_loopback:

        _lsl_loopback()
    rec = load_recording(recording)
    try:
        ports = parse_sensor_ports(osc_sensor) if osc_sensor else None
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    if ports is not None and not isinstance(ports, dict):
        raise ConfigError("--osc-sensor for the emulator: NAME=PORT (where each device sends)")

    try:
        x3 = _ximu3_ports(ximu3_sensor)
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    faults = Faults(malformed=malformed, dropout=dropout, seed=seed)
    err_console.print(f"emulating {input_name} from {recording.name} ({rec.duration:.1f} s, {len(rec.names)} sensors)",
                      highlight=False)
    try:
        res = asyncio.run(emulate_input(input_name, rec, host=host, port=port, lsl_stream=lsl_stream, osc_profile=osc_profile,
                                  osc_ports=ports, ximu3_ports=x3, ximu3_transport=ximu3_transport,
                                  ximu3_format=ximu3_format, faults=faults, speed=speed, duration=duration))
    except (ValueError, TimeoutError) as exc:  # e.g. a sensor name that is no MVN segment
        raise ConfigError(f"{recording}: {exc}") from None

    def render(r: dict[str, Any]) -> None:
        t = Table(title=f"{recording.name} as {input_name} -> {r['target']}")
        t.add_column("", overflow="fold")
        t.add_column("value", overflow="fold")
        for k in ("rate_hz", "frames_sent", "malformed_sent", "dropped_sensor_samples", "duration_s"):
            t.add_row(k, f"{r[k]:.3f}" if isinstance(r[k], float) else str(r[k]))
        console.print(t)

    _emit(res, as_json, render)

"""``wearpose serve`` (the streaming server), ``wearpose stream replay`` (stream a recording to
it) and ``wearpose view-live`` / ``wearpose view-recording`` (the browser viewer).

Thin: each command parses options and calls :mod:`wearpose.stream` or :mod:`wearpose.viewer`.
"""

from __future__ import annotations

import asyncio
import logging
from pathlib import Path
from typing import Any, List, Optional

import typer
from rich.markup import escape
from rich.table import Table

from wearpose.cli.app import _emit, app, console, err_console
from rich.progress import Progress
from wearpose.cli.models import check_pose_weights, parse_settings, recording_mismatch, with_settings
from wearpose.errors import ConfigError
from wearpose.errors import ShapeError
import tempfile

stream_app = typer.Typer(help="Clients of the streaming server (see wearpose serve).\n\n"
                              "Example: wearpose stream replay out/rec.npz --url ws://127.0.0.1:8765",
                         no_args_is_help=True)
app.add_typer(stream_app, name="stream")


def _stride(value: str) -> int | str:
    if value == "auto":
        return value
    try:
        n = int(value)
    except ValueError:
        n = 0
    if n < 1:
        raise typer.BadParameter(f"expected a positive integer or 'auto', got {value!r}", param_hint="--stride")
    return n


@app.command()
def serve(
    model: str = typer.Option("empose12_cpu", help="Shipped weights name (wearpose.weights) or a checkpoint file."),
    method: Optional[str] = typer.Option(None, help="Estimator registry name (default: from the card/checkpoint)."),
    host: str = typer.Option("127.0.0.1", help="Interface to listen on (0.0.0.0 for the network)."),
    port: int = typer.Option(8765, help="TCP port (0: any free port, printed at start)."),
    reorder_window: int = typer.Option(4, help="Lateness bound: a missing frame is given up once a frame this many "
                                               "sequence numbers newer has arrived."),
    stride: str = typer.Option("auto", help="Estimate every N-th frame: auto (default: the integer factor stream "
                                            "rate / the estimator's trained rate, e.g. 4 for 120 Hz into 30 Hz weights, "
                                            "the rule `wearpose estimate` decimates by; a stream below, or not an "
                                            "integer multiple of, that rate is refused at hello), 1 (every frame) or "
                                            "N (any rate, output may be degraded)."),
    udp_port: Optional[int] = typer.Option(None, help="Also accept the same packets over UDP on this port."),
    workers: int = typer.Option(2, min=1, help="Estimator steps running at once (each subject has its own estimator thread; "
                                        "subjects step in parallel up to this)."),
    threads: int = typer.Option(1, min=1, help="torch CPU threads per step."),
    settings: Optional[List[str]] = typer.Option(None, "--set", help="KEY=VALUE: a cost setting of every subject's "
                                                 "estimator (repeatable), as in wearpose bench latency, e.g. "
                                                 "--set online=stream (BiRAE), --set mim=true (MI-Poser), "
                                                 "--set refine_steps=3 (EM-POSE's refinement on the sensors)."),
    warmup: int = typer.Option(30, min=0, help="Synthetic steps run on each new subject's estimator before it is ready "
                                        "(pays tracing / first-call costs before real frames; 0: none)."),
    token: Optional[str] = typer.Option(None, envvar="WEARPOSE_TOKEN",
                                        help="Access token clients present (default: a random one, printed at start; "
                                             "at least 16 characters A-Z a-z 0-9 _ -)."),
    require_token: bool = typer.Option(False, "--require-token",
                                       help="Require the token on loopback too (always required on any other bind)."),
    allow_origin: Optional[List[str]] = typer.Option(None, "--allow-origin",
                                                     help="Also accept browser pages from this origin, e.g. "
                                                          "http://dashboard.lan:3000 (repeatable; such a page must "
                                                          "present the token too). Default: same-host pages only."),
    rate_limit: float = typer.Option(2000.0, min=1.0, help="Messages per second per connection; more are dropped, "
                                                           "counted and reported."),
    max_message_bytes: int = typer.Option(131072, min=1024, help="Largest message, bytes (a bigger one closes "
                                                                 "its connection)."),
    max_subscriptions: int = typer.Option(16, min=1, help="Subject ids one subscription may name (null = all "
                                                          "counts as one)."),
    max_lag: float = typer.Option(0.5, min=0.0, help="Overload policy: a frame waiting longer than this (s) with "
                                                     "newer frames queued is shed unestimated (counted); 0: never "
                                                     "shed, every frame estimated however late."),
    input_: Optional[List[str]] = typer.Option(None, "--input", help="Live device input (repeatable): lsl, osc, mvn or "
                                                                     "ximu3; "
                                                                     "the i-th feeds subject --input-subject + i "
                                                                     "(docs/devices.md)."),
    input_subject: int = typer.Option(0, help="Subject id of the first --input."),
    device_host: str = typer.Option("127.0.0.1", help="Interface the OSC and MVN inputs listen on; x-IMU3: the "
                                                      "devices' address."),
    device_rate: Optional[float] = typer.Option(None, help="Device frame rate, Hz (OSC, x-IMU3: required; MVN: "
                                                           "default 60; LSL: default the stream's nominal rate)."),
    lsl_stream: str = typer.Option("wearpose-sensors", help="--input lsl: name of the LSL sensor stream."),
    lsl_loopback: bool = typer.Option(False, "--lsl-loopback", help="Keep LSL on this machine: a liblsl config with "
                                                                   "ResolveScope machine, KnownPeers 127.0.0.1, "
                                                                   "IPv6 off (LSLAPICFG)."),
    osc_profile: str = typer.Option("ngimu", help="--input osc: address map, ngimu, generic or a YAML file."),
    osc_sensor: Optional[List[str]] = typer.Option(None, "--osc-sensor", help="--input osc: NAME=PORT (ngimu: one UDP "
                                                                              "port per device) or NAME (generic), "
                                                                              "repeatable."),
    osc_port: int = typer.Option(9000, help="--input osc, address profiles: the one UDP port."),
    mvn_port: int = typer.Option(9763, help="--input mvn: UDP port of MVN's network streamer."),
    mvn_segments: Optional[str] = typer.Option(None, help="--input mvn: tracker segments, comma-separated (e.g. "
                                                          "pelvis,head,left_forearm); default: the first datagram's."),
    mvn_character: int = typer.Option(0, help="--input mvn: MVN character ID."),
    mvn_pose_subject: Optional[int] = typer.Option(None, help="--input mvn: also publish MVN's own pose (type-02 "
                                                              "datagrams) as this subject, beside the estimate."),
    ximu3_sensor: Optional[List[str]] = typer.Option(None, "--ximu3-sensor", help="--input ximu3: NAME=PORT per "
                                                                                  "device (tcp: its TCP port; udp: "
                                                                                  "the local receive port), repeatable."),
    ximu3_transport: str = typer.Option("tcp", help="--input ximu3: tcp (connect to each device) or udp."),
    output: Optional[List[str]] = typer.Option(None, "--output", help="Pose output (repeatable): vmc (VMC over OSC) "
                                                                      "or lsl (an LSL outlet per subject)."),
    vmc_host: str = typer.Option("127.0.0.1", help="--output vmc: the VMC receiver's host."),
    vmc_port: int = typer.Option(39539, help="--output vmc: the VMC receiver's UDP port."),
    vmc_subject: int = typer.Option(0, help="--output vmc: the subject that drives the avatar."),
    lsl_out_name: str = typer.Option("wearpose-poses", help="--output lsl: stream name (NAME-SUBJECT per subject)."),
    log_level: str = typer.Option("INFO", help="Python logging level."),
    as_json: bool = typer.Option(False, "--json", help="Print the final stats as JSON at shutdown."),
) -> None:
    """Run the streaming server: sensor frames in, poses out (WebSocket, JSON or binary packets).

    Live devices (--input lsl|osc|mvn|ximu3) feed subjects directly; --output vmc|lsl sends every pose
    on to animation tools and lab recorders (docs/devices.md).

    Runs until Ctrl-C / SIGTERM, then finishes the frames it has received and closes cleanly.
    Packet formats and the security rules (Origin allow-list, access token, limits): docs/streaming.md.
    Stats: send {"type": "stats"} or GET http://HOST:PORT/stats.

    Example: wearpose serve --model empose12_cpu --port 8765

    Example: wearpose serve --model birae6_cpu --set online=stream

    Example (EM-POSE, motion unlike the corpus's; a 30 Hz model keeps up, docs/streaming.md):
    wearpose serve --model empose12_cpu --set refine_steps=3 --set refine_centre=recording
    --set refine_centre_frames=1 --set refine_centre_every=1

    Example: wearpose serve --model pip_cpu --input mvn --mvn-segments pelvis,head,left_forearm,right_forearm,left_lower_leg,right_lower_leg --output vmc
    """
    from wearpose.stream import estimator_factory, run_server  # start-up: wearpose.stream loads torch, +2.0 s to wearpose --help
    from wearpose.stream.security import Limits, check_token, new_token, normalise_origin  # start-up: wearpose.stream.security loads torch, +1.6 s to wearpose --help

    logging.basicConfig(level=log_level.upper(), format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    token = new_token() if token is None else check_token(token)
    origins = [normalise_origin(o) for o in allow_origin or []]  # a typo fails now, not at the first page
    check_pose_weights(model)
    factory = estimator_factory(model, method, threads, parse_settings(settings))
    factory()  # load once now: a checkpoint that does not fit --method, or a --set it lacks, fails here

    def started(server: Any) -> None:
        # One line a script can wait for (benchmarks/stream.py does).
        udp = f" and udp://{server.host}:{server.udp_port}" if server.udp_port is not None else ""
        print(f"serving {model} on {server.url}{udp}", flush=True)
        # The token on stderr: stdout stays the one line above (and the --json stats at the end).
        need = "required from every client" if server.token_required else \
            "optional on loopback, required from pages allowed by --allow-origin"
        err_console.print(f"access token ({need}): {server.token}\n"
                          f"  browser pages: {server.url}/?token=...; Python client, stream replay and view-live: "
                          f"--token or WEARPOSE_TOKEN", highlight=False, soft_wrap=True)

    limits = Limits(message_bytes=max_message_bytes, rate=rate_limit, subscriptions=max_subscriptions,
                    max_lag_s=max_lag or None)
    inputs, outputs = _devices(input_, device_host, device_rate, lsl_stream, lsl_loopback, osc_profile, osc_sensor,
                               osc_port, mvn_port, mvn_segments, mvn_character, output, vmc_host, vmc_port, vmc_subject,
                               lsl_out_name, mvn_pose_subject, ximu3_sensor, ximu3_transport)
    final = run_server(factory, host, port, on_start=started, reorder_window=reorder_window, stride=_stride(stride),
                       workers=workers, udp_port=udp_port, warmup=warmup, threads=threads, token=token,
                       require_token=require_token, allow_origins=origins, limits=limits, inputs=inputs,
                       outputs=outputs, input_subject=input_subject)
    _emit(final, as_json, lambda r: console.print(f"stopped; subjects served: {len(r['finished'])}, "
                                                  f"malformed messages: {r['malformed_total']}"))


def _devices(inputs: Optional[List[str]], host: str, rate: Optional[float], lsl_stream: str, lsl_loopback: bool,
             osc_profile: str, osc_sensor: Optional[List[str]], osc_port: int, mvn_port: int, mvn_segments: Optional[str],
             mvn_character: int, outputs: Optional[List[str]], vmc_host: str, vmc_port: int, vmc_subject: int,
             lsl_out_name: str, mvn_pose_subject: Optional[int] = None, ximu3_sensor: Optional[List[str]] = None,
             ximu3_transport: str = "tcp") -> tuple[list[Any], list[Any]]:
    """The --input / --output objects (library: wearpose.stream.inputs / outputs)."""
    from wearpose.stream.inputs import make_input  # start-up: wearpose.stream.inputs loads torch, +2.0 s to wearpose --help
    from wearpose.stream.inputs.osc import parse_sensor_ports  # start-up: wearpose.stream.inputs.osc loads torch, +1.9 s to wearpose --help
    from wearpose.stream.outputs import make_output  # start-up: wearpose.stream.outputs loads torch, +1.7 s to wearpose --help

    if lsl_loopback:
        _lsl_loopback()
    try:
        sensors = parse_sensor_ports(osc_sensor) if osc_sensor else None
        x3 = _ximu3_ports(ximu3_sensor)
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    segs = [x.strip() for x in mvn_segments.split(",") if x.strip()] if mvn_segments else None
    ins = [make_input(n, host=host, rate=rate, lsl_stream=lsl_stream, osc_profile=osc_profile, osc_sensors=sensors,
                      osc_port=osc_port, mvn_port=mvn_port, mvn_segments=segs, mvn_character=mvn_character,
                      mvn_pose_subject=mvn_pose_subject, ximu3_sensors=x3, ximu3_transport=ximu3_transport)
           for n in inputs or []]
    outs = [make_output(n, vmc_host=vmc_host, vmc_port=vmc_port, vmc_subject=vmc_subject, lsl_name=lsl_out_name)
            for n in outputs or []]
    return ins, outs


def _ximu3_ports(items: Optional[List[str]]) -> Optional[dict[str, int]]:
    """``--ximu3-sensor NAME=PORT`` values (the OSC parser's rule); ValueError otherwise."""
    from wearpose.stream.inputs.osc import parse_sensor_ports  # start-up: wearpose.stream.inputs.osc loads torch, +1.9 s to wearpose --help

    if not items:
        return None
    ports = parse_sensor_ports(items)
    if not isinstance(ports, dict):
        raise ValueError("--ximu3-sensor: give every device as NAME=PORT")
    return ports


def _lsl_loopback() -> None:

    from wearpose.stream.inputs.lsl import write_loopback_config  # start-up: wearpose.stream.inputs.lsl loads torch, +1.9 s to wearpose --help

    path = write_loopback_config(Path(tempfile.mkdtemp(prefix="wearpose-lsl-")) / "lsl_api.cfg")
    err_console.print(f"LSL kept on this machine: LSLAPICFG={path}", highlight=False)


@stream_app.command("replay")
def stream_replay(
    recording: Path = typer.Argument(..., help="A wearpose recording file (.npz)."),
    url: str = typer.Option("ws://127.0.0.1:8765", help="Server URL."),
    subject: int = typer.Option(0, help="Subject id (0..65535)."),
    fmt: str = typer.Option("binary", "--format", help="Packet format: binary or json."),
    speed: float = typer.Option(1.0, help="Playback speed (1 = real time)."),
    duration: Optional[float] = typer.Option(None, help="Seconds to stream, looping the recording (default: once)."),
    malformed: float = typer.Option(0.0, help="Inject a malformed message after this fraction of frames."),
    dropout: float = typer.Option(0.0, help="Per-sensor, per-frame probability of starting a 1-30 frame dropout."),
    reorder: float = typer.Option(0.0, help="Fraction of frames sent after their successor."),
    seed: int = typer.Option(0, help="Seed of the injected faults."),
    token: Optional[str] = typer.Option(None, envvar="WEARPOSE_TOKEN",
                                        help="The server's access token (printed by wearpose serve; needed when it "
                                             "requires one)."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as JSON."),
) -> None:
    """Stream a recording to a running server at real time and report latency and losses.

    Stops at once (exit code 1, with what arrived) when the server ends the subject or goes away.

    Example: wearpose stream replay out/demo-em12/recording.npz --speed 1 --dropout 0.001 --malformed 0.01
    """

    from wearpose.recording import load_recording  # start-up: wearpose.recording loads torch, +1.7 s to wearpose --help
    from wearpose.stream import Faults, replay  # start-up: wearpose.stream loads torch, +2.0 s to wearpose --help

    if fmt not in ("binary", "json"):
        raise typer.BadParameter(f"expected binary or json, got {fmt!r}", param_hint="--format")
    if not url.startswith(("ws://", "wss://")):
        raise typer.BadParameter(f"{url!r}: expected a WebSocket URL ws://HOST:PORT (what wearpose serve prints)",
                                 param_hint="--url")
    rec = load_recording(recording)
    faults = Faults(malformed=malformed, dropout=dropout, reorder=reorder, seed=seed)
    with Progress(console=err_console, disable=as_json, transient=True) as prog:
        task = prog.add_task("streaming", total=None)
        try:
            res = asyncio.run(replay(rec, url, subject=subject, fmt=fmt, speed=speed, duration=duration,
                                     faults=faults, progress=lambda k, n: prog.update(task, completed=k, total=n),
                                     token=token))
        except OSError as exc:  # nothing listening, wrong host/port, network down
            raise ConfigError(f"--url {url}: cannot connect ({exc.strerror or exc}); is a server running there? "
                              f"start one with: wearpose serve --model <weights>") from None

    def render(r: dict[str, Any]) -> None:
        t = Table(title=f"{recording.name} -> {url} (subject {subject}, {r['rate_hz']:.0f} Hz, {r['format']})")
        t.add_column("", overflow="fold")
        t.add_column("value", overflow="fold")
        for k in ("frames_sent", "frames_expected", "poses_received", "frames_lost", "frames_shed_by_server",
                  "invalid_pose_frames"):
            t.add_row(k, str(r[k]))
        for k in ("latency_ms", "transport_ms", "server_ms", "compute_ms"):
            s = r[k]
            t.add_row(f"{k} median / p99 / max", f"{s['median']} / {s['p99']} / {s['max']}")
        t.add_row("injected", str(r["injected"]))
        console.print(t)

    _emit(res, as_json, render)
    note = (res.get("ready") or {}).get("note")
    if note:  # e.g. a 120 Hz stream into weights trained at 30 Hz on a server started without --stride auto
        err_console.print(f"[yellow]warning[/]: the server says: {escape(note)}. Start it with --stride auto "
                          f"or stream at the estimator's rate.")
    for w in res.get("warnings", ()):  # overload: frames shed by the server, latency of a starved machine
        err_console.print(f"[yellow]warning[/]: {escape(w)}")
    if res.get("ended_by_server"):
        err_console.print(f"[bold red]error:[/] the stream stopped early after {res['frames_sent']} frames: "
                          f"{escape(res['ended_by_server'])}")
        raise typer.Exit(code=1)


@app.command("view-live")
def view_live(
    url: str = typer.Option("ws://127.0.0.1:8765", help="Streaming server to subscribe to."),
    port: int = typer.Option(8080, help="HTTP port of the viewer page."),
    host: str = typer.Option("127.0.0.1", help="Interface of the viewer page."),
    subject: Optional[int] = typer.Option(None, help="Only this subject (default: every subject)."),
    body: Optional[str] = typer.Option(None, help="Body asset: default, smpl or a file path."),
    token: Optional[str] = typer.Option(None, envvar="WEARPOSE_TOKEN",
                                        help="The streaming server's access token (when it requires one)."),
    allow_origin: Optional[List[str]] = typer.Option(None, "--allow-origin",
                                                     help="Also let pages from this origin open the viewer "
                                                          "(repeatable; default: this machine's pages only)."),
) -> None:
    """Browser viewer of a running server's pose stream (body mesh, skeleton, sensors).

    Open http://HOST:PORT in a browser. Runs until Ctrl-C.

    Example: wearpose serve & wearpose view-live --port 8080 & wearpose stream replay rec.npz
    """
    from wearpose.viewer.live import run_live_viewer  # start-up: wearpose.viewer.live loads torch, +1.5 s to wearpose --help

    run_live_viewer(url, host=host, port=port, subjects=None if subject is None else [subject], body=body,
                    token=token, allow_origins=allow_origin or ())


@app.command("view-recording")
def view_recording(
    recording: Path = typer.Argument(..., help="A wearpose recording (.npz; ground truth shown when it has one)."),
    model: Optional[str] = typer.Option(None, help="Estimate with these shipped weights / checkpoint and show the "
                                                   "estimate beside the ground truth."),
    port: int = typer.Option(8080, help="HTTP port of the viewer page."),
    host: str = typer.Option("127.0.0.1", help="Interface of the viewer page."),
    body: Optional[str] = typer.Option(None, help="Body asset: default, smpl or a file path."),
    allow_origin: Optional[List[str]] = typer.Option(None, "--allow-origin",
                                                     help="Also let pages from this origin open the viewer "
                                                          "(repeatable; default: this machine's pages only)."),
    resample: Optional[bool] = typer.Option(None, "--resample/--no-resample",
                                            help="As for `wearpose estimate`: decimate the recording to the weights' "
                                                 "trained rate by an integer factor (default: when the rates differ "
                                                 "by one)."),
    settings: Optional[List[str]] = typer.Option(None, "--set", help="KEY=VALUE: an inference setting of the "
                                                 "estimator (repeatable), as `wearpose estimate --set`."),
) -> None:
    """Browser viewer of a recording (ground truth and/or an estimate) with a timeline.

    Open http://HOST:PORT in a browser. Runs until Ctrl-C. The estimate is made exactly as
    `wearpose estimate` makes it (rate fitted, upright, feet on the floor).

    Example: wearpose view-recording out/demo-em12/recording.npz --model empose12_cpu
    """
    from wearpose.estimators.run import open_model  # start-up: wearpose.estimators.run loads torch, +2.0 s to wearpose --help
    from wearpose.viewer.live import run_recording_viewer  # start-up: wearpose.viewer.live loads torch, +1.5 s to wearpose --help

    source, est = None, None
    if model is not None:
        check_pose_weights(model)
        source = open_model(model)  # the checkpoint is read here, once
        est = with_settings(source.make(), parse_settings(settings), model)
    elif settings:
        raise typer.BadParameter("settings change an estimator's; give one with --model", param_hint="--set")
    try:
        run_recording_viewer(recording, model=source, host=host, port=port, body=body,
                             allow_origins=allow_origin or (), resample=resample, estimator=est)
    except ShapeError as exc:  # the estimator's check of the recording: missing sensors, another rate
        if source is None:
            raise
        raise recording_mismatch(recording, source, exc) from None

"""The hostile soak of the streaming server (``python benchmarks/stream.py --hostile``).

Two honest subjects (12 EM sensors at 120 Hz each, a held-out clip looped, two connections;
``--hostile-model``: ``null``, the pass-through estimator, by default, so that the figures are
what hostile clients do to other subjects and not how fast EM-POSE steps on a shared machine;
``empose12_cpu`` runs it at ``--stride auto``) stream for ``--duration`` seconds while, from the
same client process:

- a page of a foreign ``Origin`` tries to connect every second, without and with the token;
- a usurper connection sends the honest subjects' ``bye``, a frame and a ``hello`` for each of
  them every second (another connection's subject);
- every 5 s a connection sends a 200 KiB message (over the 128 KiB limit);
- a connection sends a malformed message every 50 ms (8 kinds, cycled), and every 30 s a
  connection floods 5000 of them at once (past the server's ``--rate-limit 1000``);
- a slow subscriber (4 KiB receive buffer) subscribes to every subject and reads 20 messages a
  second (the two subjects make 240 poses a second).

The hostile phase's server runs with ``--max-lag 0`` (never shed), so a lost frame there is one a
hostile client cost. Then the starvation phase (``--starve-duration``): a fresh server pinned to one core with
``--busy`` busy-loop processes pinned to the same core, one honest subject estimated at every
120 Hz frame (``--stride 1``): the server must shed frames by its overload policy (``shed``,
``Limits.max_lag_s``) and the replay summary must warn.

Pass: both honest subjects lose 0 frames in the hostile phase; every hostile action is refused
and counted by the server (client-side attempts = the server's counters); in the starvation phase
frames are shed and ``warnings`` is not empty. Writes ``benchmarks/results/stream_hostile.{md,json}``.
"""

from __future__ import annotations

import asyncio
import json
import os
import secrets
import signal
import subprocess
import sys
import time
import urllib.request
from pathlib import Path
from typing import Any

import numpy as np

from wearpose.stream import FramePacket, Hello, StreamClient, StreamError, replay, stack_recording
from wearpose.stream.packets import encode_frame_binary

EVIL = "http://evil.example.com"
#: The server's --rate-limit (messages/s per connection; honest devices send 120) and the flood size.
RATE_LIMIT, FLOOD = 1000, 5000
#: The slow subscriber's pause between reads: 20 messages/s against the 240 poses/s of two subjects.
SLOW_READ_S = 0.05
# The binary ones name subject 99 (no such subject): a packet for an honest subject from this
# connection would be counted not_owner, not malformed.
MALFORMED = [b"garbage", b"WP" + bytes(20), b"WP\x01\x01\x63\x00" + bytes(60), "not json", '{"type": "nope"}',
             '{"type": "frame", "subject": 99, "seq": 0}', '{"no": "type"}', "[" * 5000]


def start_server(root: Path, model: str, stride: str, token: str, cpus: set[int] | None,
                 max_lag: float = 0.5) -> tuple[subprocess.Popen, str]:
    cmd = [sys.executable, "-m", "wearpose.cli", "serve", "--model", model, "--port", "0", "--stride", stride,
           "--max-lag", str(max_lag),
           "--token", token, "--log-level", "ERROR", "--threads", "1", "--rate-limit", str(RATE_LIMIT)]
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, cwd=root, env=env,
                            preexec_fn=(lambda: os.sched_setaffinity(0, cpus)) if cpus else None)
    line = proc.stdout.readline()
    if " on ws://" not in line:
        proc.kill()
        raise RuntimeError(f"server did not start: {line!r}")
    return proc, line.strip().split(" on ")[1].split(" and ")[0]


def stop_server(proc: subprocess.Popen) -> int:
    proc.send_signal(signal.SIGINT)
    try:
        return proc.wait(60)
    except subprocess.TimeoutExpired:
        proc.kill()
        return -9


def get_stats(url: str, token: str) -> dict[str, Any]:
    req = urllib.request.Request(url.replace("ws://", "http://") + "/stats", headers={"Authorization": f"Bearer {token}"})
    with urllib.request.urlopen(req, timeout=10) as r:
        return json.loads(r.read())


async def _every(period: float, stop: asyncio.Event, fn: Any) -> None:
    while not stop.is_set():
        await fn()
        try:
            await asyncio.wait_for(stop.wait(), period)
        except asyncio.TimeoutError:
            pass


async def hostile_phase(rec: Any, url: str, token: str, duration: float, n: dict[str, int],
                        notes: dict[str, Any]) -> list[dict[str, Any]]:
    """Two honest replays and the hostile actors beside them; ``n`` counts the hostile attempts."""
    st = stack_recording(rec)
    stop = asyncio.Event()
    honest = [asyncio.create_task(replay(rec, url, subject=k, fmt="binary", realtime=True, duration=duration,
                                         drain_timeout=300.0)) for k in (0, 1)]  # a loaded machine's backlog
    await asyncio.sleep(5.0)  # both honest subjects are open (hello answered) before the usurper starts

    async def foreign_origin() -> None:
        for tok in (None, token):
            try:  # counted once answered: an attempt still in flight when /stats is read is not one yet
                c = await StreamClient(url, origin=EVIL, token=tok).connect()
                n["origin_attempts"] += 1
                n["origin_admitted"] += 1
                await c.close()
            except StreamError:
                n["origin_attempts"] += 1

    usurper = await StreamClient(url).connect()
    frame = encode_frame_binary(FramePacket(0, 0, 0.0, st.valid[0], np.nan_to_num(st.data[0])))

    async def usurp() -> None:
        for k in (0, 1):
            await usurper.send_raw(json.dumps({"type": "bye", "subject": k}))
            n["foreign_bye"] += 1
            await usurper.send_raw(bytes(frame[:4]) + k.to_bytes(2, "little") + bytes(frame[6:]))
            n["foreign_frame"] += 1
            await usurper.send_raw(json.dumps({"type": "hello", "subject": k, "sensors": list(st.names),
                                               "channels": list(st.channels), "rate": st.rate, "format": "binary"}))
            n["foreign_hello"] += 1

    async def oversize() -> None:
        c = await StreamClient(url).connect()
        n["oversize_attempts"] += 1
        await c.send_raw(b"WP" + bytes(200 * 1024))
        try:
            await asyncio.wait_for(c._reader, 10)
            notes.setdefault("oversize_close_codes", []).append(c._ws.close_code)
        except asyncio.TimeoutError:
            notes.setdefault("oversize_close_codes", []).append(None)
        await c.close()

    bad = await StreamClient(url).connect()
    k_bad = [0]

    async def malformed() -> None:
        await bad.send_raw(MALFORMED[k_bad[0] % len(MALFORMED)])
        k_bad[0] += 1
        n["malformed_sent"] += 1

    async def flood() -> None:
        c = await StreamClient(url).connect()
        for _ in range(FLOOD):
            await c.send_raw(b"garbage")
        n["flood_sent"] += FLOOD
        await asyncio.sleep(1.0)
        await c.close()

    async def slow_subscriber() -> None:
        import socket

        from websockets.asyncio.client import connect

        # A small receive buffer, so the server's socket fills after a few poses, as a stalled
        # viewer's on a network would (loopback buffers hold megabytes).
        host, port = url.split("//")[1].split(":")
        sock = socket.socket()
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        sock.setblocking(False)
        await asyncio.get_running_loop().sock_connect(sock, (host, int(port)))
        async with connect(url, sock=sock, compression=None, ping_interval=None, max_queue=4) as ws:
            await ws.send(json.dumps({"type": "subscribe", "subjects": None, "format": "json"}))
            while not stop.is_set():
                try:
                    msg = await asyncio.wait_for(ws.recv(), 5)
                except asyncio.TimeoutError:
                    continue
                n["slow_subscriber_messages"] += 1
                if '"dropped"' in msg[:40]:
                    n["slow_subscriber_drop_reports"] += 1
                    notes["slow_subscriber_dropped_total_reported"] = json.loads(msg).get("total")
                await asyncio.sleep(SLOW_READ_S)

    actors = [asyncio.create_task(_every(1.0, stop, foreign_origin)), asyncio.create_task(_every(1.0, stop, usurp)),
              asyncio.create_task(_every(5.0, stop, oversize)), asyncio.create_task(_every(0.05, stop, malformed)),
              asyncio.create_task(_every(30.0, stop, flood)), asyncio.create_task(slow_subscriber())]
    # The actors stop 3 s before the honest streams end: a bye or frame for a subject that has
    # already ended is answered as an unknown subject, not counted as another's (not_owner).
    await asyncio.sleep(max(0.0, duration - 8.0))
    stop.set()
    await asyncio.gather(*actors, return_exceptions=True)
    results = await asyncio.gather(*honest)
    await asyncio.sleep(1.0)  # the last refusals reach the counters
    notes["usurper_errors_received"] = sum(1 for m in usurper.messages if m.get("code") == "not_owner")
    await usurper.close()
    await bad.close()
    return results


def busy_loops(k: int, cpus: set[int]) -> list[subprocess.Popen]:
    code = "import os; os.sched_setaffinity(0, %r)\nwhile True: pass" % (cpus,)
    return [subprocess.Popen([sys.executable, "-c", code]) for _ in range(k)]


def run(args: Any, rec: Any, root: Path, git: dict[str, Any], machine: dict[str, Any]) -> dict[str, Any]:
    token = secrets.token_urlsafe(32)
    n = dict.fromkeys(("origin_attempts", "origin_admitted", "foreign_bye", "foreign_frame", "foreign_hello",
                       "oversize_attempts", "malformed_sent", "flood_sent", "slow_subscriber_messages",
                       "slow_subscriber_drop_reports"), 0)
    notes: dict[str, Any] = {}
    out: dict[str, Any] = {"command": "python benchmarks/stream.py " + " ".join(sys.argv[1:]), "git": git,
                           "machine": machine, "utc_start": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                           "duration_s": args.duration, "starve_duration_s": args.starve_duration}
    # Honest subjects through the pass-through estimator by default: the soak measures what hostile
    # clients do to other subjects; on a shared 2-core machine EM-POSE's own steps can fall behind
    # without any hostile client (then the overload policy sheds, which is the starvation phase's test).
    model = args.hostile_model
    # --max-lag 0 (never shed) here: a loss in this phase is then what hostile clients did, not the
    # overload policy reacting to the shared machine's load (the starvation phase tests that).
    proc, url = start_server(root, model, "auto" if model != "null" else "1", token, None, max_lag=0.0)
    try:
        honest = asyncio.run(hostile_phase(rec, url, token, args.duration, n, notes))
        stats = get_stats(url, token)
    finally:
        rc = stop_server(proc)
    sec = stats["security"]
    checks = {
        "honest_subjects_lost_0": all(r["frames_lost"] == 0 and r["ended_by_server"] is None for r in honest),
        "foreign_origin_refused_and_counted": n["origin_admitted"] == 0 and sec["origin"] == n["origin_attempts"],
        "foreign_bye_frame_hello_refused_and_counted": sec["not_owner"] == n["foreign_bye"] + n["foreign_frame"] + n["foreign_hello"],
        "oversize_refused_and_counted": sec["oversize"] == n["oversize_attempts"]
                                        and all(c == 1009 for c in notes.get("oversize_close_codes", [])),
        "malformed_and_flood_counted": stats["malformed_total"] + sec["rate_limited"] == n["malformed_sent"] + n["flood_sent"]
                                       and sec["rate_limited"] > 0,
        "slow_subscriber_dropped_oldest_and_told": stats["subscriber_dropped"] > 0 and n["slow_subscriber_drop_reports"] > 0,
    }
    out["hostile"] = {"model": model, "attempts": n, "server_security": sec, "server_malformed_total": stats["malformed_total"],
                      "server_subscriber_dropped": stats["subscriber_dropped"], "server_exit_code": rc, "notes": notes,
                      "honest": [{k: r[k] for k in ("subject", "frames_sent", "frames_expected", "poses_received",
                                                    "frames_lost", "frames_shed_by_server", "ended_by_server",
                                                    "latency_ms", "warnings")}
                                 | {"refused_foreign": r["server_stats"].get("refused_foreign")} for r in honest],
                      "checks": checks}
    # Starvation: the server and busy loops on one core.
    cpus = {min(os.sched_getaffinity(0))}
    proc, url = start_server(root, args.weights, "1", token, cpus)  # EM-POSE on every 120 Hz frame
    busy = busy_loops(args.busy, cpus)
    try:
        starved = asyncio.run(replay(rec, url, subject=0, fmt="binary", realtime=True, duration=args.starve_duration,
                                     drain_timeout=60.0, token=token))
    finally:
        for b in busy:
            b.kill()
        rc2 = stop_server(proc)
    out["starved"] = {"busy_loops_pinned_with_server": args.busy, "cpus": sorted(cpus), "server_exit_code": rc2,
                      **{k: starved[k] for k in ("frames_sent", "frames_expected", "poses_received", "frames_lost",
                                                 "frames_shed_by_server", "frames_lost_by_server", "latency_ms",
                                                 "server_ms", "compute_ms", "warnings", "ended_by_server")},
                      "checks": {"server_shed_load": starved["frames_shed_by_server"] > 0,
                                 "replay_summary_warns": bool(starved["warnings"]),
                                 "latency_bounded_by_policy": starved["latency_ms"]["median"] is not None
                                                              and starved["latency_ms"]["median"] < 1000.0}}
    out["utc_end"] = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    out["machine"]["load_average_end"] = [round(x, 2) for x in os.getloadavg()]
    out["passed"] = all(checks.values()) and all(out["starved"]["checks"].values())
    return out


def markdown(r: dict[str, Any]) -> str:
    h, s = r["hostile"], r["starved"]
    a, sec = h["attempts"], h["server_security"]
    rows = [
        ("foreign Origin (without / with the token)", a["origin_attempts"], f"{sec['origin']} refused (HTTP 403), {a['origin_admitted']} admitted",
         h["checks"]["foreign_origin_refused_and_counted"]),
        ("another connection's bye / frame / hello", f"{a['foreign_bye']} / {a['foreign_frame']} / {a['foreign_hello']}",
         f"{sec['not_owner']} not_owner ({h['notes'].get('usurper_errors_received')} error replies; {sec['errors_suppressed']} suppressed)",
         h["checks"]["foreign_bye_frame_hello_refused_and_counted"]),
        ("200 KiB message (limit 128 KiB)", a["oversize_attempts"], f"{sec['oversize']} oversize, closed 1009",
         h["checks"]["oversize_refused_and_counted"]),
        ("malformed messages + floods of 5000", f"{a['malformed_sent']} + {a['flood_sent']}",
         f"{h['server_malformed_total']} malformed + {sec['rate_limited']} rate_limited", h["checks"]["malformed_and_flood_counted"]),
        ("slow subscriber (20 messages/s)", f"{a['slow_subscriber_messages']} read",
         f"{h['server_subscriber_dropped']} poses dropped oldest, {a['slow_subscriber_drop_reports']} dropped reports",
         h["checks"]["slow_subscriber_dropped_oldest_and_told"]),
    ]
    lines = [f"# Hostile soak of the streaming server", "",
             f"`{r['command']}`; commit `{r['git'].get('commit', '')[:7]}`"
             f"{' (uncommitted src edits)' if r['git'].get('src_uncommitted') else ''}; {r['utc_start']} - {r['utc_end']}; "
             f"load average {r['machine']['load_average_start'][0]} at the start, {r['machine']['load_average_end'][0]} at the end "
             f"({r['machine']['cpus']} cores, shared).", "",
             f"Hostile phase: {r['duration_s']:g} s, two honest subjects (12 EM sensors at 120 Hz, estimator "
             f"`{h['model']}`{', every frame' if h['model'] == 'null' else ', `--stride auto`'}) on their own connections.", "",
             "| honest subject | frames sent | expected | poses | lost | of which shed (overload) | end-to-end median / p99 / max ms | refused foreign |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for x in h["honest"]:
        L = x["latency_ms"]
        lines.append(f"| {x['subject']} | {x['frames_sent']:,} | {x['frames_expected']:,} | {x['poses_received']:,} | "
                     f"**{x['frames_lost']}** | {x['frames_shed_by_server']} | {L['median']} / {L['p99']} / {L['max']} | {x['refused_foreign']} |")
    lines += ["", "| hostile action | attempts (client) | server counted | refused and counted |", "| --- | --- | --- | --- |"]
    lines += [f"| {a_} | {b} | {c} | {'yes' if d else '**NO**'} |" for a_, b, c, d in rows]
    L = s["latency_ms"]
    lines += ["", f"Starvation: {r['starve_duration_s']:g} s, one subject at every 120 Hz frame (`--stride 1`), the server "
              f"and {s['busy_loops_pinned_with_server']} busy loops pinned to CPU {s['cpus']}.", "",
              "| frames expected | poses | shed by the server | end-to-end median / p99 / max ms | replay warnings |",
              "| --- | --- | --- | --- | --- |",
              f"| {s['frames_expected']:,} | {s['poses_received']:,} | {s['frames_shed_by_server']:,} | "
              f"{L['median']} / {L['p99']} / {L['max']} | {'; '.join(s['warnings']) or 'none'} |", "",
              f"Checks: {'all passed' if r['passed'] else 'FAILED'} "
              f"({', '.join(k for k, v in {**h['checks'], **s['checks']}.items() if not v) or 'none failed'})."]
    return "\n".join(lines) + "\n"

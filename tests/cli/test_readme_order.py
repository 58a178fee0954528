"""README.md's command blocks, run in the written order in a fresh temporary directory.

What "fresh" means here (as a user who has just cloned the repository):

- the working directory is a new folder holding the checkout's ``run.sh`` and ``pyproject.toml``
  and ``.venv`` (a link to the venv running this test: ``./run.sh test`` has just installed the
  pins into it; when its install stamp does not match ``pyproject.toml``, ``./run.sh X`` runs as
  ``.venv/bin/wearpose X`` so this test never reinstalls into a shared venv); ``../shared`` beside
  it links to the real ``shared`` folder (corpus v2 and the real sensor logs, read only);
- ``HOME`` and its caches are new and empty, no ``WEARPOSE_*`` variable is set, so every store,
  output and weights cache comes from the commands themselves;
- the files README's "your own data" lines name are written first, small and synthetic:
  ``~/mocap/s01/take.bvh``, ``mocap/walk.bvh``, ``take.bvh`` (a corpus clip exported to BVH) and
  ``DIP_IMU/s_01/01.pkl`` (a DIP-IMU layout pickle).

Every line of every ```bash block is one command (``#`` starts a comment), run with bash after
the block's ``. .venv/bin/activate`` line; the ```python block runs as a script at its place.
Limits are appended, never substituted, so each command is the one README shows (for a repeated
option the last value counts): see :data:`LIMITS`. Long-running commands (``serve``,
``view-live``, ``view-recording``) start in the background, are waited for until they say they
are ready, and are stopped with SIGINT (expected exit 0) when the commands that use them have run.
Free ports replace the defaults 8765/8080, which other programs on a shared machine may hold.
"""

from __future__ import annotations

import os
import re
import resource
import shlex
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
README = REPO / "README.md"

#: (command prefix, appended arguments, why). ``{serve}``/``{viewer}`` are free ports.
LIMITS: list[tuple[str, str, str]] = [
    ("./run.sh demo", "--seconds 2", "the first 2 s of the clip (README's demo uses 10 s)"),
    ("wearpose demo", "--seconds 2", "the first 2 s of the clip"),
    ("./run.sh test", f"{REPO}/tests/geometry/test_heading.py -q -p no:cacheprovider",
     "one small test file: the whole suite is CI's own run (and would run this test again)"),
    ("wearpose data prepare ~/mocap", "--workers 1", "one process"),
    ("wearpose data prepare", "--per-split 1 --clip cmu_daz/05/05_01 --workers 1",
     "a store of the first clip of each split and source plus the clip README names (~10 clips, not 1862)"),
    ("wearpose simulate", "--limit 2 --workers 1", "two clips of the split"),
    ("wearpose train empose --sensors 12 --config cpu", "--limit 1 --epochs 1 --threads 1", "one clip, one epoch"),
    ("wearpose evaluate", "--clips 1", "one test clip"),
    ("torchrun", "--limit 1 --epochs 1", "one clip, one epoch"),
    ("wearpose serve", "--port {serve}", "a free port"),
    ("wearpose stream replay", "--url ws://127.0.0.1:{serve} --duration 3", "3 s of the recording"),
    ("wearpose view-live", "--url ws://127.0.0.1:{serve} --port {viewer}", "a free port"),
    ("wearpose view-recording", "--port {viewer2}", "a free port"),
]
#: Background commands and the text each prints once ready.
BACKGROUND = {"wearpose serve": " on ws://", "wearpose view-live": "subscribed to", "wearpose view-recording": "viewer on "}
#: Seconds one command may take before the test calls it a hang.
COMMAND_TIMEOUT_S = 600  # a loaded machine: a demo took 60-90 s at load 12-20


def readme_blocks(text: str) -> list[tuple[str, list[str] | str]]:
    """``[("bash", [command, ...]) | ("python", source), ...]`` in README order."""
    out: list[tuple[str, list[str] | str]] = []
    for lang, body in re.findall(r"```(bash|python)\n(.*?)```", text, re.S):
        if lang == "python":
            out.append(("python", body))
            continue
        cmds = []
        for line in body.splitlines():
            cmd = line.split(" #", 1)[0].strip() if not line.lstrip().startswith("#") else ""
            if cmd:
                cmds.append(cmd)
        out.append(("bash", cmds))
    return out


def with_limits(cmd: str, ports: dict[str, int]) -> str:
    """``cmd`` with the first matching :data:`LIMITS` entry's arguments appended."""
    for prefix, extra, _ in LIMITS:
        if cmd.startswith(prefix) or (prefix == "torchrun" and cmd.startswith("torchrun")):
            return f"{cmd} {extra.format(**ports)}"
    return cmd


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _user_files(work: Path, home: Path) -> None:
    """The files README's 'your own data' lines name, small and synthetic."""
    import gzip
    import pickle

    import numpy as np
    import torch

    from wearpose.geometry import axis_angle_to_matrix

    # A corpus BVH cut to 2 s: the user's own take.
    src = _shared_dir() / "data-v2" / "cmu_daz" / "05" / "05_01.bvh.gz"
    lines = gzip.decompress(src.read_bytes()).decode().splitlines()
    i = next(k for k, ln in enumerate(lines) if ln.startswith("Frames:"))
    n = int(round(2.0 / float(lines[i + 1].split(":")[1])))
    cut = lines[:i] + [f"Frames: {n}", lines[i + 1]] + lines[i + 2:i + 2 + n]
    for p in (home / "mocap" / "s01" / "take.bvh", work / "mocap" / "walk.bvh", work / "take.bvh"):
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text("\n".join(cut) + "\n")
    # DIP-IMU layout: 17 sensors' orientations and accelerations, SMPL pose (72).
    rng = np.random.default_rng(0)
    T = 60
    aa = np.cumsum(rng.normal(scale=0.02, size=(T, 17, 3)), axis=0)
    ori = axis_angle_to_matrix(torch.from_numpy(aa)).numpy()
    dip = work / "DIP_IMU" / "s_01" / "01.pkl"
    dip.parent.mkdir(parents=True)
    with open(dip, "wb") as fh:
        pickle.dump({"imu_ori": ori, "imu_acc": rng.normal(scale=0.5, size=(T, 17, 3)),
                     "gt": rng.normal(scale=0.1, size=(T, 72)), "imu": np.zeros((T, 17, 12))}, fh, protocol=2)


def _shared_dir() -> Path:
    from wearpose.motion import data_dir

    return data_dir().parent


def _stamp_is_current() -> bool:
    import hashlib

    h = hashlib.sha256((REPO / "pyproject.toml").read_bytes()).hexdigest()[:16]
    return (Path(sys.prefix) / f".wearpose-installed-{h}").is_file()


@pytest.mark.corpus
# Measured 271-277 s on the quiet 2-core machine (two runs, 2026-12-01): ~40 commands of 3-16 s each,
# most of it interpreter + torch start-up per command (issue 25), no single slow one. Issue 22 asks
# for under 3 minutes: not met yet, so the budget states what it takes. With demo --seconds 2
# (2026-12-02, load 8-14): 303 s CPU over all commands (the log prints each command's CPU); a
# demo's cost is mostly fixed (miposer 18.4 s CPU at 2 s of clip vs 21.7 s at 10 s, load 3-4).
# The fresh-machine CI run of 2c8556c (quiet machine) took 289.6 s: 10 s under the old 300 s
# budget, so the budget was 360 s. The latest clean CI run took 158.8 s (quiet machine, 2 cores, load ~1.5):
# the budget is issue 22's "under 3 minutes", 180 s. Per command most of it is the interpreter and
# torch's import (2.3 s CPU of doctor's 3.6, info's 3.0, data info's 2.8, view's 3.1, recording import's
# 5.6 s, 2026-12-03): each of these needs torch (doctor checks it, info/view build the body, data info and
# recording import reach it through wearpose.motion / wearpose.recording), so no lazy import removes it.
@pytest.mark.budget(180)
def test_readme_commands_run_in_written_order(tmp_path: Path) -> None:
    try:
        shared = _shared_dir()
    except Exception as exc:  # noqa: BLE001 - no corpus: the commands cannot run
        pytest.skip(f"../shared/data-v2 absent ({exc})")
    root = tmp_path / "fresh"
    work, home = root / "wearpose", root / "home"
    work.mkdir(parents=True)
    home.mkdir()
    for f in ("run.sh", "pyproject.toml"):
        (work / f).write_bytes((REPO / f).read_bytes())
    (work / "run.sh").chmod(0o755)
    (work / ".venv").symlink_to(sys.prefix, target_is_directory=True)
    (root / "shared").symlink_to(shared, target_is_directory=True)
    _user_files(work, home)
    env = {k: v for k, v in os.environ.items() if not k.startswith("WEARPOSE_") and k not in ("VIRTUAL_ENV", "PYTHONPATH")}
    env.update(HOME=str(home), XDG_CACHE_HOME=str(home / ".cache"), MPLCONFIGDIR=str(home / ".config" / "mpl"),
               OMP_NUM_THREADS="1", COLUMNS="80", PYTHONUNBUFFERED="1")
    env["PATH"] = os.pathsep.join(p for p in env.get("PATH", "").split(os.pathsep) if not p.startswith(sys.prefix))
    ports = {"serve": _free_port(), "viewer": _free_port(), "viewer2": _free_port()}
    stamp_ok = _stamp_is_current()
    log: list[str] = []
    background: list[tuple[str, subprocess.Popen]] = []
    t_all, c_all = time.perf_counter(), _children_cpu_s()
    try:
        for lang, block in readme_blocks(README.read_text(encoding="utf-8")):
            if lang == "python":
                script = work / "readme_example.py"
                script.write_text(block)
                _run(f"{work}/.venv/bin/python readme_example.py", work, env, log)
                continue
            prelude = ""
            for cmd in block:
                if cmd.startswith((". ", "source ")):
                    prelude = cmd + " && "
                    continue
                full = with_limits(cmd, ports)
                if full.startswith("./run.sh") and not stamp_ok:
                    sub = full.split(None, 2)
                    rest = sub[2] if len(sub) > 2 else ""
                    full = (f".venv/bin/python -m pytest {rest}" if sub[1] == "test" else f".venv/bin/wearpose {sub[1]} {rest}")
                    _note(log, f"(venv stamp does not match pyproject.toml: ran {full!r} for {cmd!r})")
                bg = next((k for k in BACKGROUND if cmd.startswith(k)), None)
                if bg is not None:
                    background.append((cmd, _start(prelude + full, work, env, BACKGROUND[bg], log)))
                else:
                    _run(prelude + full, work, env, log)
            for cmd, proc in reversed(background):
                _stop(cmd, proc, log)
            background.clear()
    finally:
        for _, proc in background:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
        print("\n".join(log))
        print(f"README in order: {time.perf_counter() - t_all:.0f} s, cpu {_children_cpu_s() - c_all:.0f} s of its commands "
              f"(load average {os.getloadavg()[0]:.1f})")
    # Each command's outputs, where README names one, exist.
    for p in ("out/demo-em12/recording.npz", "out/demo-em6", "out/demo-imu6", "out/demo-mimu6", "out/demo-miposer",
              "out/demo-roundtrip", "sims/em12/cmu_daz/05/05_01.npz", "sims/imu6", "recs/ximu3-lower-body.npz",
              "legs.bvh", "walk.html", "walk.glb", "pose.bvh", "results/em12.md", "motion_npz"):
        assert (work / p).exists(), f"README command output {p} missing"


def _children_cpu_s() -> float:
    """CPU seconds (user + system) of every waited-for child process so far."""
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def _note(log: list[str], line: str) -> None:
    """Keep ``line`` for the summary and show it at once (``pytest -s``: progress of a long run)."""
    log.append(line)
    print(line, flush=True)


def _run(cmd: str, cwd: Path, env: dict[str, str], log: list[str]) -> None:
    t0, c0 = time.perf_counter(), _children_cpu_s()
    try:
        r = subprocess.run(["bash", "-c", cmd], cwd=cwd, env=env, capture_output=True, text=True, timeout=COMMAND_TIMEOUT_S)
    except subprocess.TimeoutExpired as exc:
        pytest.fail(f"README command hung (> {COMMAND_TIMEOUT_S} s): {cmd}\n{exc.stdout}\n{exc.stderr}")
    _note(log, f"{time.perf_counter() - t0:6.1f} s  cpu {_children_cpu_s() - c0:5.1f} s  rc {r.returncode}  {cmd}")
    assert r.returncode == 0, f"README command failed in README order: {cmd}\n--- stdout\n{r.stdout[-3000:]}\n--- stderr\n{r.stderr[-3000:]}"


def _as_in_a_terminal() -> None:
    """In the child before exec: Ctrl-C's default action, as a command typed in a terminal has it.
    A test run started as a background job of a non-interactive shell (``.ci/run &``) inherits
    SIGINT ignored, and Python then installs no KeyboardInterrupt handler: `wearpose
    view-recording` slept on through the test's Ctrl-C (its stacks, 2026-12-03)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _start(cmd: str, cwd: Path, env: dict[str, str], ready: str, log: list[str]) -> subprocess.Popen:
    proc = subprocess.Popen(["bash", "-c", "exec " + cmd if not cmd.startswith(". ") else cmd.replace(" && ", " && exec ", 1)],
                            cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True, preexec_fn=_as_in_a_terminal)
    t0, seen = time.perf_counter(), []
    while time.perf_counter() - t0 < COMMAND_TIMEOUT_S:
        line = proc.stdout.readline()
        if not line and proc.poll() is not None:
            pytest.fail(f"README command exited before it was ready (rc {proc.returncode}): {cmd}\n{''.join(seen)[-3000:]}")
        seen.append(line)
        if ready in line:
            _note(log, f"{time.perf_counter() - t0:6.1f} s  ready  {cmd}")
            return proc
    os.killpg(proc.pid, signal.SIGKILL)
    pytest.fail(f"README command not ready after {COMMAND_TIMEOUT_S} s: {cmd}\n{''.join(seen)[-3000:]}")


def _stop(cmd: str, proc: subprocess.Popen, log: list[str]) -> None:
    c0 = _children_cpu_s()
    os.killpg(proc.pid, signal.SIGINT)
    try:
        out, _ = proc.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGUSR1)  # every thread's stack to its output (wearpose.cli.app.main)
        time.sleep(2)
        os.killpg(proc.pid, signal.SIGKILL)
        out, _ = proc.communicate()
        pytest.fail(f"README command did not stop on Ctrl-C within 30 s: {cmd}\n--- its output and stacks\n{out[-8000:]}")
    _note(log, f"  stopped rc {proc.returncode}  cpu {_children_cpu_s() - c0:5.1f} s (its whole run)  {cmd}")
    assert proc.returncode == 0, f"README command ended with {proc.returncode} on Ctrl-C: {cmd}\n{out[-3000:]}"


def test_limits_only_append() -> None:
    """The limits keep README's command as written: the command is a prefix of what runs."""
    ports = {"serve": 1, "viewer": 2, "viewer2": 3}
    cmds = [c for lang, b in readme_blocks(README.read_text(encoding="utf-8")) if lang == "bash" for c in b]
    assert any(c.startswith("wearpose serve") for c in cmds) and any(c.startswith("./run.sh test") for c in cmds)
    for c in cmds:
        assert with_limits(c, ports).startswith(c)
    assert with_limits("wearpose evaluate empose12_cpu --clips 20", ports).endswith("--clips 1")

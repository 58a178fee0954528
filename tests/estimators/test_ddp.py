"""Distributed training: ``shard_batch`` and 2-process DDP runs (torchrun, gloo on CPU) against 1 process.

Acceptance of issue 8: a 2-process DDP run of a tiny training config gives the same loss curve
as a 1-process run with the same global batch.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from wearpose.errors import ConfigError
from wearpose.estimators.train import shard_batch

WORKER = Path(__file__).with_name("ddp_worker.py")


def _has_store() -> bool:
    try:
        from wearpose.motion import CorpusStore

        return len(CorpusStore().clips(split="train")) > 0 and len(CorpusStore().clips(split="val")) > 0
    except Exception:
        return False


def _env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("WORLD_SIZE", "RANK", "LOCAL_RANK", "MASTER_ADDR", "MASTER_PORT")}
    env["OMP_NUM_THREADS"] = "1"
    return env


def _run(nproc: int, *args: str, out: Path, timeout: float = 300.0, attempts: int = 2) -> None:
    """Run the worker with ``nproc`` processes; ``out`` is its run directory (unique per call).

    A 2-process gloo run on this 2-core machine hung once in a few dozen CI runs (both ranks past
    their first step, then no progress for 10 min; it did not reproduce in repeated runs). A hang
    is therefore retried once from an empty ``out``; a second hang, a non-zero exit or a wrong
    result still fails the test.
    """
    if nproc == 1:  # the plain single-process path, no torchrun at all
        cmd = [sys.executable, *args]
    else:
        cmd = [sys.executable, "-m", "torch.distributed.run", "--standalone", f"--nproc_per_node={nproc}", *args]
    for attempt in range(1, attempts + 1):
        shutil.rmtree(out, ignore_errors=True)
        # Own process group: on a timeout the whole group (torchrun and its workers) is killed, so a
        # rank waiting in a collective for a dead partner cannot outlive the test.
        proc = subprocess.Popen(cmd, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                start_new_session=True)
        try:
            stdout, stderr = proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            # torchrun may start its workers in sessions of their own: they survive killpg and keep
            # our pipes open, so find them by their unique run directory.
            subprocess.run(["pkill", "-9", "-f", str(out)], check=False)
            try:
                stdout, stderr = proc.communicate(timeout=30)
            except subprocess.TimeoutExpired:
                stdout, stderr = "", ""
            if attempt < attempts:
                print(f"attempt {attempt} timed out after {timeout:g} s, retrying: {' '.join(cmd)}", file=sys.stderr)
                continue
            raise AssertionError(f"timed out after {timeout:g} s, {attempts} attempts: {' '.join(cmd)}\n"
                                 f"{stderr[-3000:]}") from None
        assert proc.returncode == 0, stdout[-3000:] + stderr[-3000:]
        return


def _log(out: Path) -> tuple[list[float], list[dict]]:
    rows = [json.loads(line) for line in (out / "log.jsonl").read_text().splitlines()]
    return [r["loss"] for r in rows if r["type"] == "step"], [r for r in rows if r["type"] in ("start", "epoch")]


def test_shard_batch_slices_and_weights() -> None:
    b = {"x": torch.arange(10).view(5, 2), "y": (torch.arange(5), torch.ones(5, 3)), "name": "keep"}
    parts = [shard_batch(b, r, 2) for r in range(2)]
    assert [p["x"].shape[0] for p, _ in parts] == [2, 3]
    assert torch.equal(torch.cat([p["x"] for p, _ in parts]), b["x"])
    assert parts[1][0]["y"][1].shape == (3, 3) and parts[0][0]["name"] == "keep"
    # weights make the DDP average of slice means the global mean: sum_r w_r * mean_r / world
    w = [wt for _, wt in parts]
    assert w == pytest.approx([2 * 2 / 5, 2 * 3 / 5])
    vals = torch.arange(5.0)
    avg = sum(wt * float(vals[p["y"][0]].mean()) for p, wt in parts) / 2
    assert avg == pytest.approx(float(vals.mean()))


def test_shard_batch_rejects_bad_batches() -> None:
    with pytest.raises(ConfigError, match="batch size >= the number of processes"):
        shard_batch(torch.zeros(1, 3), 0, 2)
    with pytest.raises(ConfigError, match="one leading batch size"):
        shard_batch({"a": torch.zeros(4), "b": torch.zeros(3)}, 0, 2)


def test_two_process_ddp_equals_one_process_on_a_synthetic_task(tmp_path: Path) -> None:
    _run(1, str(WORKER), "synthetic", str(tmp_path / "one"), out=tmp_path / "one")
    _run(2, str(WORKER), "synthetic", str(tmp_path / "two"), out=tmp_path / "two")
    one, rows1 = _log(tmp_path / "one")
    two, rows2 = _log(tmp_path / "two")
    assert len(one) == len(two) == 8
    assert rows1[0]["world_size"] == 1 and rows2[0]["world_size"] == 2
    assert two == pytest.approx(one, rel=1e-5)
    assert one[-1] < 0.5 * one[0]  # it trained


@pytest.mark.corpus
@pytest.mark.skipif(not _has_store(), reason="no prepared corpus store (wearpose data prepare)")
def test_two_process_ddp_matches_one_process_on_the_empose_tiny_config(tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    curves = {}
    for kind in ("empose-nobn", "empose"):
        for n in (1, 2):
            _run(n, str(WORKER), kind, str(tmp_path / f"{kind}{n}"), str(cache), out=tmp_path / f"{kind}{n}")
            curves[kind, n] = _log(tmp_path / f"{kind}{n}")
    # Without batch norm every rank computes exactly its share: the curves are equal.
    a, b = curves["empose-nobn", 1][0], curves["empose-nobn", 2][0]
    assert len(a) == len(b) >= 10
    assert b == pytest.approx(a, rel=1e-4)
    # With the shipped batch norms (per-rank statistics) the curves agree within 10 % per step
    # (measured: <= 7 % over 12 steps), and the validation losses too.
    a, b = curves["empose", 1][0], curves["empose", 2][0]
    assert len(a) == len(b) and b == pytest.approx(a, rel=0.10)
    va = [r["val_loss"] for r in curves["empose", 1][1] if r["type"] == "epoch"]
    vb = [r["val_loss"] for r in curves["empose", 2][1] if r["type"] == "epoch"]
    assert len(va) == 3 and vb == pytest.approx(va, rel=0.10) and va[-1] < va[0]


@pytest.mark.corpus
@pytest.mark.skipif(not _has_store(), reason="no prepared corpus store (wearpose data prepare)")
def test_wearpose_train_runs_unchanged_under_torchrun(tmp_path: Path) -> None:
    out = tmp_path / "run"
    _run(2, "-m", "wearpose.cli", "train", "empose", "--config", "tiny", "--limit", "2", "--epochs", "1",
         "--threads", "1", "--out", str(out), "--json", out=out)
    _, rows = _log(out)
    assert rows[0]["world_size"] == 2 and (out / "best.pt").is_file() and (out / "last.pt").is_file()

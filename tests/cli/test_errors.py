"""User mistakes on the command line: one clear line naming the file, the field, the problem and
the expected form, a non-zero exit, and no traceback.

Commands run through :func:`wearpose.cli.main` (the console entry point, which turns library and
file-system errors into that line) or through typer's runner for option errors (exit code 2).
"""

from __future__ import annotations

import importlib
import signal
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from tests.sensors.sensor_testutils import smooth_motion
from wearpose.cli import app, main
from wearpose.recording import Recording, save_recording

runner = CliRunner()


def run_main(args: list[str], capsys, monkeypatch) -> tuple[int, str]:
    """``wearpose ARGS`` as a user runs it: (exit code, stderr with lines joined)."""
    app_module = importlib.import_module("wearpose.cli.app")  # the module; wearpose.cli.app is the Typer

    monkeypatch.setattr(sys, "argv", ["wearpose", *args])
    monkeypatch.setattr(app_module.err_console, "width", 10_000)  # one line per message, no wrapping
    monkeypatch.delenv("WEARPOSE_DEBUG", raising=False)
    monkeypatch.setattr(warnings, "showwarning", warnings.showwarning)  # main() replaces it; restored after
    with pytest.raises(SystemExit) as ex:
        main()
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    code = ex.value.code if isinstance(ex.value.code, int) else 1
    return code, " ".join(err.split())


def flat(output: str) -> str:
    """typer's error box as one line: borders dropped, whitespace joined."""
    return " ".join(output.replace("│", " ").split())


def _simulated(kit: str, T: int = 30, fps: float = 30.0, rate: float | None = None) -> Recording:
    from wearpose.body import BodyModel
    from wearpose.sensors import simulate

    m = smooth_motion(T=T, fps=fps, seed=1, dtype=torch.float32)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = simulate(m, kit, BodyModel(), seed=2, noise="none", offsets="random", rate=rate)
    return Recording.from_simulation(res, m)


@pytest.fixture(scope="module")
def em_file(tmp_path_factory) -> Path:
    """A valid em12 recording at 30 Hz (the rate of the shipped empose12_cpu)."""
    path = tmp_path_factory.mktemp("err") / "em12.npz"
    save_recording(_simulated("em12", rate=30.0), path)
    return path


def _rewrite(src: Path, dst: Path, **changes: np.ndarray) -> Path:
    with np.load(src) as z:
        d = {k: z[k] for k in z.files}
    d.update(changes)
    np.savez(dst, **d)
    return dst


# ----------------------------------------------------------------------------- recording files
def test_missing_recording_names_the_file(tmp_path: Path, capsys, monkeypatch) -> None:
    code, err = run_main(["calibrate", str(tmp_path / "nope.npz"), "--method", "empose-offsets"], capsys, monkeypatch)
    assert code == 1 and "nope.npz: file not found" in err and "Expected: a wearpose.recording .npz" in err


def test_truncated_recording_says_damaged_or_truncated(em_file: Path, tmp_path: Path, capsys, monkeypatch) -> None:
    cut = tmp_path / "cut.npz"
    raw = em_file.read_bytes()
    cut.write_bytes(raw[: len(raw) // 2])  # an interrupted copy
    code, err = run_main(["stream", "replay", str(cut)], capsys, monkeypatch)
    assert code == 1 and "cut.npz: a damaged or truncated npz (zip) archive" in err


def test_a_file_of_another_type_is_named_as_such(tmp_path: Path, capsys, monkeypatch) -> None:
    txt = tmp_path / "notes.npz"
    txt.write_text("time,x,y,z\n0,1,2,3\n")
    code, err = run_main(["stream", "replay", str(txt)], capsys, monkeypatch)
    assert code == 1 and "notes.npz: not an npz (zip) archive" in err
    assert "pickle" not in err  # numpy's advice about pickled data is not the problem here


def test_nan_in_a_valid_frame_names_the_field(em_file: Path, tmp_path: Path, capsys, monkeypatch) -> None:
    with np.load(em_file) as z:
        pos = z["sensors/head/position"].copy()
    pos[5] = np.nan
    bad = _rewrite(em_file, tmp_path / "nan.npz", **{"sensors/head/position": pos})
    code, err = run_main(["calibrate", str(bad), "--method", "empose-offsets"], capsys, monkeypatch)
    # The [field] used to vanish: rich read it as a markup tag.
    assert code == 1 and "nan.npz [sensors/head/position]: NaN or infinite value in valid frame 5" in err
    assert "Expected: finite values wherever valid is True" in err


def test_positions_in_millimetres_are_caught(em_file: Path, tmp_path: Path, capsys, monkeypatch) -> None:
    with np.load(em_file) as z:
        pos = z["sensors/head/position"] * 1000.0
    bad = _rewrite(em_file, tmp_path / "mm.npz", **{"sensors/head/position": pos})
    code, err = run_main(["stream", "replay", str(bad)], capsys, monkeypatch)
    assert code == 1 and "[sensors/head/position]" in err and "looks like millimetres" in err


def test_quaternions_written_x_y_z_w_name_the_field_and_the_fix(em_file: Path, tmp_path: Path, capsys, monkeypatch) -> None:
    # Issue 22: such a file used to be estimated silently wrong (16.6 cm mean joint difference).
    with np.load(em_file) as z:
        wrong = {k: z[k][:, [1, 2, 3, 0]] for k in z.files if k.endswith("/orientation")}
    bad = _rewrite(em_file, tmp_path / "xyzw.npz", **wrong)
    code, err = run_main(["estimate", str(bad), "--model", "empose12_cpu", "--out", str(tmp_path / "p.npz")], capsys, monkeypatch)
    assert code == 1 and "xyzw.npz [sensors/" in err and "/orientation]" in err
    assert "the quaternions look written (x, y, z, w)" in err and "rewrite them w-first: q[..., [3, 0, 1, 2]]" in err
    assert not (tmp_path / "p.npz").exists()


# ----------------------------------------------------------------------------- recording vs weights
@pytest.fixture
def no_viewer(monkeypatch) -> None:
    """view-recording must fail before it starts serving; if it got that far the test fails."""
    import wearpose.viewer.live as live

    def refuse(*a, **k):
        raise AssertionError("the viewer started on a recording that does not fit the weights")

    monkeypatch.setattr(live, "RecordingViewer", refuse)


def test_recording_of_another_kit_names_file_kit_and_remedy(tmp_path: Path, capsys, monkeypatch, no_viewer) -> None:
    imu = tmp_path / "imu6.npz"
    save_recording(_simulated("imu6", rate=60.0, fps=60.0), imu)
    code, err = run_main(["view-recording", str(imu), "--model", "empose12_cpu", "--port", "0"], capsys, monkeypatch)
    assert code == 1 and "imu6.npz: does not fit empose12_cpu (no sensors ['" in err
    assert "Expected: a recording of kit em12 at 30 Hz" in err


def test_recording_at_another_rate_names_the_rate_to_simulate(tmp_path: Path, capsys, monkeypatch, no_viewer) -> None:
    fast = tmp_path / "em12_120.npz"
    save_recording(_simulated("em12", T=60, fps=60.0), fast)  # the kit's own EM rate, 120 Hz
    # --no-resample: as `wearpose estimate --no-resample`, another rate is refused with the rate to simulate
    code, err = run_main(["view-recording", str(fast), "--model", "empose12_cpu", "--port", "0", "--no-resample"],
                         capsys, monkeypatch)
    assert code == 1 and "em12_120.npz: does not fit empose12_cpu" in err and "[rate] is 120 Hz; 30 Hz, the rate EM-POSE was trained at" in flat(err)
    assert "wearpose simulate --kit em12 --rate 30" in err


def test_view_recording_decimates_as_estimate_does(tmp_path: Path, capsys, monkeypatch) -> None:
    """Issue 22: view-recording refused the 120 Hz recordings that estimate accepts; both now take
    the same path (wearpose.estimators.run), so the viewer gets the 30 Hz estimate and says so."""
    import wearpose.viewer.live as live
    from wearpose.estimators.run import open_model

    fast = tmp_path / "em12_120.npz"
    save_recording(_simulated("em12", T=60, fps=60.0), fast)  # the kit's own EM rate, 120 Hz
    seen = {}

    class Viewer:
        def __init__(self, rec, track, **kw):
            seen.update(rate=rec.sensor(rec.names[0]).info.rate, fps=track.fps, frames=track.num_frames)
            raise KeyboardInterrupt  # stop where the viewer would start serving

    monkeypatch.setattr(live, "RecordingViewer", Viewer)
    with pytest.raises(KeyboardInterrupt):
        live.run_recording_viewer(fast, model=open_model("empose12_cpu"), port=0)
    assert seen["rate"] == 30.0 and seen["fps"] == 30.0 and seen["frames"] > 0
    assert "decimated by 4 to empose12_cpu's 30 Hz" in capsys.readouterr().out


def test_view_recording_applies_settings_as_estimate_does(tmp_path: Path, monkeypatch) -> None:
    """``view-recording --set``: the estimate shown is made with the settings (EM-POSE's
    refinement: every frame refined); ``--set`` without ``--model`` is refused."""
    import wearpose.viewer.live as live
    from typer.testing import CliRunner

    from wearpose.cli import app

    rec = tmp_path / "em12.npz"
    save_recording(_simulated("em12", T=20, rate=30.0), rec)
    seen = {}

    class Viewer:
        def __init__(self, rec, track, **kw):
            seen.update(refined=track.extras.get("refined"))
            raise KeyboardInterrupt  # stop where the viewer would start serving

    monkeypatch.setattr(live, "RecordingViewer", Viewer)
    res = CliRunner().invoke(app, ["view-recording", str(rec), "--model", "empose12_cpu", "--port", "0",
                                   "--set", "refine_steps=1"])
    assert seen["refined"] is not None and bool(seen["refined"].all()), res.output
    res = CliRunner().invoke(app, ["view-recording", str(rec), "--port", "0", "--set", "refine_steps=1"])
    assert res.exit_code == 2 and "--model" in flat(res.output)


@pytest.mark.parametrize("cmd", [["serve", "--port", "0"], ["view-recording", "x.npz"], ["evaluate"]])
def test_weights_that_are_not_an_estimator_are_refused(cmd: list[str]) -> None:
    args = [*cmd, "nbeats_cpu"] if cmd == ["evaluate"] else [*cmd, "--model", "nbeats_cpu"]
    res = runner.invoke(app, args)
    assert res.exit_code == 2, res.output
    text = flat(res.output)
    assert "'nbeats_cpu' is not a pose estimator" in text and "empose12_cpu" in text


def test_serve_refuses_weights_of_another_method_before_serving(capsys, monkeypatch) -> None:
    import wearpose.stream as stream

    monkeypatch.setattr(stream, "run_server", lambda *a, **k: pytest.fail("served a mismatched checkpoint"))
    code, err = run_main(["serve", "--model", "pip_cpu", "--method", "empose", "--port", "0"], capsys, monkeypatch)
    assert code == 1 and "pip_cpu.pt: checkpoint is for method 'pip', not 'empose'" in err


def test_unknown_estimator_name_lists_the_known_ones(capsys, monkeypatch) -> None:
    code, err = run_main(["serve", "--model", "empose12_cpu", "--method", "emposee", "--port", "0"], capsys, monkeypatch)
    assert code == 1 and "unknown estimator 'emposee'; available:" in err and "pip" in err


def test_replay_without_a_server_says_how_to_start_one(em_file: Path, capsys, monkeypatch) -> None:
    code, err = run_main(["stream", "replay", str(em_file), "--url", "ws://127.0.0.1:9"], capsys, monkeypatch)
    assert code == 1 and "--url ws://127.0.0.1:9: cannot connect" in err and "wearpose serve" in err
    res = runner.invoke(app, ["stream", "replay", str(em_file), "--url", "http://127.0.0.1:9"])
    assert res.exit_code == 2 and "ws://HOST:PORT" in flat(res.output)


# ----------------------------------------------------------------------------- calibrate / evaluate options
def test_calibrate_unknown_sensor_and_reversed_window(em_file: Path) -> None:
    res = runner.invoke(app, ["calibrate", str(em_file), "--method", "tpose", "--sensor", "left_wirst"])
    text = flat(res.output)
    assert res.exit_code == 2 and "no sensor 'left_wirst'" in text and "head" in text
    res = runner.invoke(app, ["calibrate", str(em_file), "--method", "tpose", "--window", "5", "1"])
    assert res.exit_code == 2 and "0 <= START < STOP" in flat(res.output)


def test_counts_must_be_positive() -> None:
    # --clips 0 used to mean "the whole split" (a long run instead of an error).
    res = runner.invoke(app, ["evaluate", "empose12_cpu", "--clips", "0"])
    assert res.exit_code == 2 and "--clips" in flat(res.output)


# ----------------------------------------------------------------------------- motion files
def _amass(path: Path, T: int = 20, **over: np.ndarray) -> Path:
    d = {"poses": np.zeros((T, 156)), "trans": np.zeros((T, 3)) + [0.0, 0.0, 0.95], "betas": np.zeros(16),
         "mocap_framerate": np.array(60.0)}
    d.update(over)
    np.savez(path, **d)
    return path


def test_amass_translation_in_centimetres(tmp_path: Path, capsys, monkeypatch) -> None:
    f = _amass(tmp_path / "cm.npz", trans=np.zeros((20, 3)) + [0.0, 0.0, 95.0])
    code, err = run_main(["view", str(f), "--out", str(tmp_path / "v.html")], capsys, monkeypatch)
    assert code == 1 and "cm.npz [trans]: |trans| reaches 95" in err and "looks like centimetres" in err
    assert not (tmp_path / "v.html").exists()


def test_amass_angles_in_degrees(tmp_path: Path, capsys, monkeypatch) -> None:
    poses = np.zeros((20, 156))
    poses[:, 3 * 18 + 2] = 90.0  # left elbow bent 90 "radians": degrees
    f = _amass(tmp_path / "deg.npz", poses=poses)
    code, err = run_main(["export", str(f), str(tmp_path / "o.bvh")], capsys, monkeypatch)
    assert code == 1 and "deg.npz [poses]" in err and "looks like degrees" in err


def test_amass_wrong_shape_and_missing_key(tmp_path: Path, capsys, monkeypatch) -> None:
    f = _amass(tmp_path / "short.npz", poses=np.zeros((20, 70)))
    code, err = run_main(["view", str(f)], capsys, monkeypatch)
    assert code == 1 and "short.npz [poses]: shape (20, 70)" in err and "(T, 156) SMPL-H or (T, 72) SMPL" in err
    np.savez(tmp_path / "notrans.npz", poses=np.zeros((5, 72)), betas=np.zeros(10), mocap_framerate=30.0)
    code, err = run_main(["view", str(tmp_path / "notrans.npz")], capsys, monkeypatch)
    assert code == 1 and "notrans.npz [trans]: missing key" in err


def test_a_recording_given_as_motion_points_to_view_recording(em_file: Path, capsys, monkeypatch) -> None:
    code, err = run_main(["view", str(em_file)], capsys, monkeypatch)
    assert code == 1 and "is a wearpose recording (sensor data), not a motion" in err and "view-recording" in err


def test_motion_import_checks_options_once(tmp_path: Path, capsys, monkeypatch) -> None:
    bvh = tmp_path / "a.bvh"
    bvh.write_text("HIERARCHY\n")
    res = runner.invoke(app, ["motion", "import", str(bvh), "--units", "furlong"])
    assert res.exit_code == 2 and "furlong" in flat(res.output)
    res = runner.invoke(app, ["motion", "import", str(bvh), "--up", "q"])
    assert res.exit_code == 2 and "y, -y, z, -z, x, -x" in flat(res.output)
    res = runner.invoke(app, ["motion", "import", str(bvh), str(tmp_path / "typo.bvh")])
    assert res.exit_code == 2 and "typo.bvh" in flat(res.output)
    jm = tmp_path / "map.yaml"
    jm.write_text("pelvs: Hips\n")
    code, err = run_main(["motion", "import", str(bvh), "--joint-map", str(jm)], capsys, monkeypatch)
    assert code == 1 and "map.yaml [pelvs]: unknown key 'pelvs'" in err


def test_truncated_bvh_names_the_frame(tmp_path: Path, capsys, monkeypatch) -> None:
    from tests.motion.test_motion_bvh import SAMPLE

    f = tmp_path / "cut.bvh"
    f.write_text(SAMPLE.rstrip()[:-20] + "\n")  # the last frame line cut short, as by an interrupted copy
    code, err = run_main(["view", str(f)], capsys, monkeypatch)
    assert code == 1 and "cut.bvh" in err and "frame 1 has" in err and "16 numbers per frame line" in err


# ----------------------------------------------------------------------------- file system
def test_output_under_a_file_is_one_line_not_a_traceback(tmp_path: Path, capsys, monkeypatch) -> None:
    f = _amass(tmp_path / "ok.npz")
    blocker = tmp_path / "file.txt"
    blocker.write_text("x")
    code, err = run_main(["export", str(f), str(blocker / "out.bvh")], capsys, monkeypatch)
    assert code == 1 and err.startswith("error:") and "file.txt: is a file, but the output path needs a folder" in err


def test_data_prepare_of_only_broken_files_fails(tmp_path: Path) -> None:
    (tmp_path / "mocap" / "actor1").mkdir(parents=True)
    (tmp_path / "mocap" / "actor1" / "take.bvh").write_text("not a bvh\n")
    res = runner.invoke(app, ["data", "prepare", str(tmp_path / "mocap"), "--cache", str(tmp_path / "store"),
                              "--workers", "1"])
    assert res.exit_code == 1 and "no MOTION section" in flat(res.output)


def test_replay_passes_on_the_servers_rate_warning(em_file: Path, monkeypatch) -> None:
    import wearpose.stream as stream

    async def fake_replay(rec, url, **kw):
        return {"ready": {"note": "the estimator was trained at 30 Hz but receives 120 Hz (stream 120 Hz, stride 1)"}}

    monkeypatch.setattr(stream, "replay", fake_replay)
    res = runner.invoke(app, ["stream", "replay", str(em_file), "--json"])
    assert res.exit_code == 0, res.output
    assert "trained at 30 Hz but receives 120 Hz" in flat(res.output) and "--stride auto" in flat(res.output)


def test_clip_id_without_a_corpus_says_to_set_wearpose_data(tmp_path: Path, capsys, monkeypatch) -> None:
    monkeypatch.setenv("WEARPOSE_DATA", str(tmp_path / "no_corpus"))
    monkeypatch.setenv("WEARPOSE_CACHE", str(tmp_path / "no_store"))
    code, err = run_main(["view", "cmu_daz/05/05_01"], capsys, monkeypatch)
    assert code == 1 and "cmu_daz/05/05_01: no such motion" in err and "set WEARPOSE_DATA" in err


@pytest.mark.skipif(not hasattr(signal, "SIGUSR1"), reason="no SIGUSR1 on this platform")
def test_sigusr1_prints_every_threads_stack_and_the_command_runs_on() -> None:
    """A command that will not stop can be asked where it is (`kill -USR1 PID`): the entry point
    registers a stack dump; the process is not ended by it."""
    code = ("import os, signal, threading, time\n"
            "from wearpose.cli.app import dump_stacks_on_sigusr1\n"
            "dump_stacks_on_sigusr1()\n"
            "def parked():\n    time.sleep(5)\n"
            "threading.Thread(target=parked, daemon=True).start()\n"
            "time.sleep(0.2)\n"
            "os.kill(os.getpid(), signal.SIGUSR1)\n"
            "print('still running')\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert "still running" in r.stdout
    assert "in parked" in r.stderr and "Current thread" in r.stderr, r.stderr

"""``wearpose estimate``: a recording + shipped weights -> a motion file."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tests.cli.test_errors import _simulated, flat, run_main
from wearpose.cli import app
from wearpose.export import read_export_metadata
from wearpose.motion import load_motion
from wearpose.recording import Recording, save_recording

runner = CliRunner()


@pytest.fixture(scope="module")
def em12_30(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("est") / "em12.npz"
    save_recording(_simulated("em12", T=30, rate=30.0), path)
    return path


def test_help_has_an_example() -> None:
    res = runner.invoke(app, ["estimate", "--help"])
    assert res.exit_code == 0 and "Example: wearpose estimate" in flat(res.output)


def test_estimate_writes_a_motion_that_reads_back(em12_30: Path, tmp_path: Path) -> None:
    out = tmp_path / "pose.npz"
    res = runner.invoke(app, ["estimate", str(em12_30), "--model", "empose12_cpu", "--out", str(out), "--json"])
    assert res.exit_code == 0, res.output
    r = json.loads(res.stdout)
    assert r["frames"] == 30 and r["fps"] == 30.0 and r["frame"] == "world" and r["estimated_frame"] == "em_source" and r["written"] == str(out)
    seq = load_motion(str(out))  # AMASS-style npz, as `wearpose export` writes
    assert seq.num_frames == 30 and seq.pose.shape == (30, 24, 3, 3)


RUNNING_TURN = ["--set", "refine_steps=3", "--set", "refine_centre=recording", "--set", "refine_centre_frames=1",
                "--set", "refine_centre_every=1"]


def test_estimate_applies_inference_settings(em12_30: Path, tmp_path: Path) -> None:
    """``--set``: EM-POSE's refinement with the running turn changes the estimate and is reported."""
    plain, refined = tmp_path / "plain.npz", tmp_path / "refined.npz"
    res = runner.invoke(app, ["estimate", str(em12_30), "--model", "empose12_cpu", "--out", str(plain), "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["settings"] == {}
    res = runner.invoke(app, ["estimate", str(em12_30), "--model", "empose12_cpu", "--out", str(refined), "--json",
                              *RUNNING_TURN])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["settings"] == {"refine_steps": "3", "refine_centre": "recording",
                                                  "refine_centre_frames": "1", "refine_centre_every": "1"}
    a, b = load_motion(str(plain)), load_motion(str(refined))
    assert a.pose.shape == b.pose.shape and float((a.pose - b.pose).abs().amax()) > 1e-3
    assert read_export_metadata(plain)["estimator"] == {"model": "empose12_cpu", "settings": {}}
    assert read_export_metadata(refined)["estimator"]["settings"]["refine_centre_frames"] == "1"  # the file says how


def test_estimate_refuses_an_unknown_setting_naming_the_ones_it_has(em12_30: Path, tmp_path: Path) -> None:
    out = tmp_path / "p.npz"
    res = runner.invoke(app, ["estimate", str(em12_30), "--model", "empose12_cpu", "--out", str(out),
                              "--set", "refine_stpes=3"])
    text = flat(res.output)
    assert res.exit_code == 2 and "refine_stpes" in text and "refine_steps" in text, text
    assert not out.exists()


def test_estimate_refuses_a_recording_of_another_kit(tmp_path: Path, capsys, monkeypatch) -> None:
    imu = tmp_path / "imu.npz"
    save_recording(_simulated("imu6", T=30, fps=60.0, rate=60.0), imu)
    code, err = run_main(["estimate", str(imu), "--model", "empose12_cpu", "--out", str(tmp_path / "p.bvh")],
                         capsys, monkeypatch)
    assert code == 1 and "imu.npz: does not fit empose12_cpu" in err and "kit em12 at 30 Hz" in err
    assert not (tmp_path / "p.bvh").exists()


def test_imu_recording_without_a_tpose_says_how_to_calibrate(tmp_path: Path, capsys, monkeypatch) -> None:
    imu = tmp_path / "imu.npz"
    save_recording(_simulated("imu6", T=90, fps=60.0, rate=60.0), imu)  # moving from the first frame on
    code, err = run_main(["estimate", str(imu), "--model", "pip_cpu", "--out", str(tmp_path / "p.bvh")],
                         capsys, monkeypatch)
    assert code == 1 and "imu.npz: pip_cpu could not calibrate it" in err and "--method tpose --window" in err


def test_estimate_output_format_is_checked_first(em12_30: Path, tmp_path: Path) -> None:
    res = runner.invoke(app, ["estimate", str(em12_30), "--model", "empose12_cpu", "--out", str(tmp_path / "p.fbx")])
    assert res.exit_code == 2 and ".bvh, .npz or .glb" in flat(res.output)


def test_rotation_only_estimator_exports_on_the_default_body(tmp_path: Path) -> None:
    """BiRAE keeps no body model of its own (it used to fail: 'no body model to export on')."""
    mimu = tmp_path / "mimu.npz"
    save_recording(_simulated("mimu6", T=30, fps=60.0, rate=60.0), mimu)
    out = tmp_path / "b.bvh"
    res = runner.invoke(app, ["estimate", str(mimu), "--model", "birae6_cpu", "--out", str(out), "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["frames"] == 30 and out.stat().st_size > 0


def test_library_warnings_are_one_line(tmp_path: Path, capsys, monkeypatch) -> None:
    import warnings

    from wearpose.errors import ConfigError

    def stop(*a, **k):
        warnings.warn("MI-Poser: no calibration", UserWarning)
        raise ConfigError("stop here")

    monkeypatch.setattr("wearpose.recording.load_recording", stop)
    code, err = run_main(["estimate", "x.npz", "--model", "empose12_cpu", "--out", str(tmp_path / "p.bvh")],
                         capsys, monkeypatch)
    assert code == 1 and "warning: MI-Poser: no calibration" in err and "UserWarning" not in err


def _imu_with_tpose(hold_s: float, mark: bool) -> Recording:
    """imu6 at 60 Hz on a moving motion that opens with a ``hold_s`` T-pose (site orientations,
    as `wearpose simulate` writes them), the window marked in meta or not."""
    import warnings

    import torch

    from tests.sensors.sensor_testutils import smooth_motion
    from wearpose.body import BodyModel
    from wearpose.recording import CALIBRATION_WINDOW_KEY, Recording, prepend_tpose
    from wearpose.sensors import simulate

    m, window = prepend_tpose(smooth_motion(T=60, fps=60.0, seed=1, dtype=torch.float32), hold_s, blend_s=0.25)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = simulate(m, "imu6", BodyModel(), seed=2, noise="none", rate=60.0)
    return Recording.from_simulation(res, m, meta={CALIBRATION_WINDOW_KEY: window} if mark else {})


def test_imu_recording_with_a_marked_tpose_is_estimated_by_pip(tmp_path: Path, capsys, monkeypatch) -> None:
    """`simulate --tpose` marks its hold; estimate calibrates PIP on that window. A 0.6 s hold
    is shorter than PIP's default 1 s window, so without the mark the same file is refused."""
    marked, unmarked = tmp_path / "marked.npz", tmp_path / "unmarked.npz"
    save_recording(_imu_with_tpose(0.6, mark=True), marked)
    save_recording(_imu_with_tpose(0.6, mark=False), unmarked)
    out = tmp_path / "p.npz"
    res = runner.invoke(app, ["estimate", str(marked), "--model", "pip_cpu", "--out", str(out), "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["frames"] == 60 + 36 + 15 and load_motion(str(out)).num_frames == 111
    code, err = run_main(["estimate", str(unmarked), "--model", "pip_cpu", "--out", str(tmp_path / "q.npz")],
                         capsys, monkeypatch)
    assert code == 1 and "could not calibrate" in err and "meta['calibration_window']" in err


def test_a_120_hz_recording_is_decimated_to_the_weights_rate_with_one_warning(tmp_path: Path, capsys,
                                                                               monkeypatch) -> None:
    rec = tmp_path / "em120.npz"
    save_recording(_simulated("em12", T=30, rate=120.0), rec)  # 1 s of motion: 120 EM samples
    code, err = run_main(["estimate", str(rec), "--model", "empose12_cpu", "--out", str(tmp_path / "p.npz"), "--json"],
                         capsys, monkeypatch)
    assert code in (0, None) and err.count("warning:") == 1
    assert "120 Hz decimated by 4 to empose12_cpu's 30 Hz" in err and "--no-resample" in err
    assert load_motion(str(tmp_path / "p.npz")).num_frames == 30
    code, err = run_main(["estimate", str(rec), "--model", "empose12_cpu", "--out", str(tmp_path / "q.npz"),
                          "--no-resample"], capsys, monkeypatch)
    assert code == 1 and "does not fit empose12_cpu" in err and "[rate] is 120 Hz; 30 Hz, the rate EM-POSE was trained at" in flat(err)


def test_a_non_integer_rate_ratio_is_refused_not_interpolated(tmp_path: Path, capsys, monkeypatch) -> None:
    rec = tmp_path / "em45.npz"
    save_recording(_simulated("em12", T=30, rate=45.0), rec)
    code, err = run_main(["estimate", str(rec), "--model", "empose12_cpu", "--out", str(tmp_path / "p.npz")],
                         capsys, monkeypatch)
    assert code == 1 and "does not fit empose12_cpu" in err and "warning" not in err  # auto: left to the estimator
    code, err = run_main(["estimate", str(rec), "--model", "empose12_cpu", "--out", str(tmp_path / "p.npz"),
                          "--resample"], capsys, monkeypatch)
    assert code == 1 and "--resample: sensors 'back', " in err and "cannot resample 45 Hz to 30 Hz (a factor of 1.5, not an integer)" in err
    assert not (tmp_path / "p.npz").exists()


def test_serve_defaults_to_stride_auto(monkeypatch) -> None:
    """`wearpose serve` estimates at the weights' trained rate unless told otherwise."""
    import wearpose.stream as stream

    seen = {}

    def fake_run_server(factory, host, port, **kw):  # noqa: ANN001, ANN202
        seen.update(kw)
        return {"finished": [], "malformed_total": 0}

    monkeypatch.setattr(stream, "run_server", fake_run_server)
    res = runner.invoke(app, ["serve", "--model", "null"])
    assert res.exit_code == 0, res.output
    assert seen["stride"] == "auto"
    res = runner.invoke(app, ["serve", "--model", "null", "--stride", "1"])
    assert res.exit_code == 0 and seen["stride"] == 1


# --------------------------------------------------------------------------- declared conventions
#: Every non-canonical convention of the recording format (docs/formats.md) at once.
def _pose_weights() -> list[str]:
    from wearpose.cli.models import pose_weights

    return pose_weights()


@pytest.mark.budget(45)  # three estimates of 3 s; PIP's physics and MI-Poser's calibration are the slow ones
@pytest.mark.parametrize("model", _pose_weights())
def test_declared_units_and_frames_give_the_same_estimate(model: str, record_property) -> None:
    """A recording and its copies written in mm and in cm, deg/s, g, sensor-frame acceleration
    with gravity and a Z-up world (each declared) give the same estimate in the world within 1e-4
    (issue 21: two estimators ignored the declaration, 2.88 and 1714 apart). Nothing is written:
    the one estimate path (estimators.run) in memory; benchmarks/declared_units.py records the
    figures."""
    import torch

    from tests.sensors.sensor_testutils import smooth_motion
    from wearpose.estimators.run import open_model
    from wearpose.evaluate.conventions import DECLARATIONS, declared_differences, kit_recording

    s = open_model(model)
    s.estimator_class  # a method may register its own kit (IMUPoser's) when imported
    fps = float(s.fps or 60.0)
    rec = kit_recording(s.kit, smooth_motion(T=int(2 * fps), fps=fps, seed=1, dtype=torch.float32), fps)
    diff = declared_differences(s, rec)
    record_property("max_abs_difference", json.dumps(diff))
    assert set(diff) == set(DECLARATIONS) == {"mm", "cm"}
    assert all(d and max(d.values()) < 1e-4 for d in diff.values()), diff


# --------------------------------------------------------------------------- exports in the world
DEMO_MODELS = {"em12": "empose12_cpu", "em6": "empose6_cpu", "imu6": "pip_cpu", "mimu6": "birae6_cpu",
               "miposer": "miposer_cpu"}


@pytest.fixture(scope="module")
def walk(corpus_root: Path):
    from wearpose.motion import CorpusStore

    seq = CorpusStore(corpus_root).load("cmu_daz/05/05_01")  # a held-out walk (test split), 60 fps
    # From 0.1 s: the clip's first stored frame is a capture glitch (its right foot 7 cm lower,
    # its lowest vertex 4.4 cm lower, than 1/60 s later), and the T-pose placed on that frame
    # sank 5.4 cm; the estimate's first walking frames after that jump are not a walk's floor.
    start = int(round(0.1 * seq.fps))
    return seq.slice(start, start + int(2 * seq.fps))


def test_exports_state_their_frame_in_the_file(em12_30: Path, tmp_path: Path) -> None:
    """The frame and placement ``estimate --json`` prints are in the exported file itself, read
    back with readers other than wearpose's: trimesh (GLB scene extras) and the raw glTF JSON
    (``asset.extras``), numpy (the npz key), json (the BVH sidecar)."""
    import numpy as np
    import trimesh

    from wearpose.export.gltf import read_glb

    metas, printed = {}, {}
    for ext in ("glb", "npz", "bvh"):
        out = tmp_path / f"pose.{ext}"
        res = runner.invoke(app, ["estimate", str(em12_30), "--model", "empose12_cpu", "--out", str(out), "--json"])
        assert res.exit_code == 0, res.output
        printed[ext] = json.loads(res.stdout)
        if ext == "glb":
            metas[ext] = read_glb(out)[0]["asset"]["extras"]
            assert trimesh.load(out).metadata["frame"] == metas[ext]["frame"]
        elif ext == "npz":
            with np.load(out, allow_pickle=False) as d:
                metas[ext] = json.loads(str(d["wearpose_metadata"]))
        else:
            assert printed[ext]["metadata"] == str(tmp_path / "pose.bvh.json")
            metas[ext] = json.loads((tmp_path / "pose.bvh.json").read_text())
    for ext, m in metas.items():
        assert m["placement"] == printed[ext]["placement"] and m["floor"] == printed[ext]["floor"], ext
        assert m["estimated"] is True and m["frames"] == printed[ext]["frames"] and m["fps"] == printed[ext]["fps"]
    assert metas["glb"]["frame"] == {"up": "+Y", "facing": "+Z", "left": "+X", "handedness": "right", "units": "m"}
    assert metas["bvh"]["frame"] == {**metas["glb"]["frame"], "units": "cm"}
    assert metas["npz"]["frame"] == {"up": "+Z", "facing": "-Y", "left": "+X", "handedness": "right", "units": "m"}


#: Standing frames: the ground truth's lowest vertex within this of its floor (its median lowest height), m.
STANDING_TOL_M = 0.03
#: An export stands on the floor when its lowest vertex is within this of y = 0 in every standing frame (m).
FLOOR_TOL_M = 0.05


def _floor_problems(motion, body, standing) -> list[str]:
    """What keeps ``motion`` (re-imported) from standing: per standing frame (``(T,)`` bool), the
    lowest vertex more than :data:`FLOOR_TOL_M` off y = 0 or the pelvis not above both knees."""
    import torch

    with torch.no_grad():
        out = body(motion.pose, motion.betas, motion.trans, return_normals=False)
    low = out.vertices[..., 1].amin(-1)  # (T,) lowest vertex per frame, m (the feet, standing)
    J = out.joints
    problems = []
    off = standing & (low.abs() >= FLOOR_TOL_M)
    if bool(off.any()):
        t = int(off.nonzero()[0])
        problems.append(f"{int(off.sum())} of {int(standing.sum())} standing frames off the floor "
                        f"(first: frame {t}, lowest vertex at {float(low[t]) * 100:.1f} cm; "
                        f"range {float(low[standing].min()) * 100:.1f}..{float(low[standing].max()) * 100:.1f} cm)")
    sunk = standing & ~(J[:, 0, 1] > J[:, 4:6, 1].max(-1).values)  # pelvis above both knees
    if bool(sunk.any()):
        problems.append(f"pelvis not above the knees in {int(sunk.sum())} standing frames")
    return problems


@pytest.mark.corpus
@pytest.mark.budget(40)  # PIP's physics and MI-Poser's calibration on 3 s
@pytest.mark.parametrize("kit", [*DEMO_MODELS, "em12-no-source-pose"])
def test_exported_bvh_stands_on_the_floor(kit: str, walk, tmp_path: Path) -> None:
    """Every demo kit's estimate of a walk, exported as BVH and read back, stands in every
    standing frame (the ground truth's feet on its floor: the held T-pose, which
    recording.prepend_tpose stands on the walk's floor, and the walk; the 0.5 s slerp from the
    T-pose into the walk is not captured motion and not checked): lowest vertex within 5 cm of the
    floor, pelvis above the knees.
    A copy of the export that rises 20 cm over the clip (first frame as exported, so the lowest
    point over all frames is unchanged) fails the same check: a body drifting up is caught. The
    BVH's sidecar states Y up."""
    import warnings

    import torch

    from wearpose.body import BodyModel
    from wearpose.estimators.run import open_model
    from wearpose.export import write_smpl_bvh
    from wearpose.motion import MotionSequence, resample
    from wearpose.recording import CALIBRATION_WINDOW_KEY, prepend_tpose
    from wearpose.sensors import simulate

    name = kit.split("-")[0]
    model = DEMO_MODELS[name]
    fps = float(open_model(model).fps or 60.0)
    m, window = prepend_tpose(resample(walk, fps) if abs(walk.fps - fps) > 1e-6 else walk, 1.0)
    body = BodyModel()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = simulate(m, name, body, seed=2, noise="none", rate=fps)
    rec = Recording.from_simulation(res, m, meta={CALIBRATION_WINDOW_KEY: window})
    if kit.endswith("no-source-pose"):
        rec.meta.pop("em_source", None)
    save_recording(rec, tmp_path / "rec.npz")
    res = runner.invoke(app, ["estimate", str(tmp_path / "rec.npz"), "--model", model, "--out",
                              str(tmp_path / "pose.bvh"), "--json"])
    assert res.exit_code == 0, res.output
    back = load_motion(str(tmp_path / "pose.bvh"))
    assert json.loads((tmp_path / "pose.bvh.json").read_text())["frame"]["up"] == "+Y"
    with torch.no_grad():
        gt_low = body(m.pose, m.betas, m.trans, return_normals=False).vertices[..., 1].amin(-1)  # (T,) m
    walk_frames = int(round(window["prefix_s"] * fps))
    standing = (gt_low - gt_low.median()).abs() < STANDING_TOL_M
    hold = int(round(window["stop_s"] * fps)) + 1
    standing[hold:walk_frames] = False  # the slerp from the T-pose into the walk: no captured motion
    assert back.num_frames == m.num_frames and int(standing[walk_frames:].sum()) > 0.8 * (m.num_frames - walk_frames)

    trans = back.trans.clone()
    trans[:, 1] += torch.linspace(0.0, 0.2, back.num_frames)  # drifts up 20 cm
    write_smpl_bvh(MotionSequence(back.pose, back.betas, trans, back.fps, {}), tmp_path / "raised.bvh",
                   body.rest_joints(back.betas))
    raised = _floor_problems(load_motion(str(tmp_path / "raised.bvh")), body, standing)
    assert raised and "off the floor" in raised[0], raised

    assert _floor_problems(back, body, standing) == [], (kit, json.loads(res.stdout)["placement"])

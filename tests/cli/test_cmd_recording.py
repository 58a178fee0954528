"""``wearpose recording import``: each format on tiny synthetic files in the dataset's own layout
(as the converter tests in tests/recording write them), options passed through, bad files -> exit 1."""

from __future__ import annotations

import json
import pickle
from pathlib import Path

import numpy as np
import torch
from typer.testing import CliRunner

from tests.recording.recording_testutils import rotations
from wearpose.cli import app
from wearpose.geometry import matrix_to_quat
from wearpose.recording import load_recording

runner = CliRunner()


def _write_dip(path: Path, T: int = 30) -> None:
    rng = np.random.default_rng(0)
    ori = np.stack([rotations(T, seed=i) for i in range(17)], axis=1)
    acc = rng.normal(size=(T, 17, 3))
    ori[[3, 4, 5], 7] = np.nan  # left forearm drops out for 3 of 30 frames
    acc[[3, 4, 5], 7] = np.nan
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as fh:
        pickle.dump({"imu_ori": ori, "imu_acc": acc, "gt": rng.normal(scale=0.2, size=(T, 72))}, fh, protocol=2)


def _write_tc(path: Path, T: int = 12, names: tuple[str, ...] = ("Head", "R_LowArm", "Pelvis")) -> None:
    rng = np.random.default_rng(2)
    lines = [f"{len(names)}\t{T}"]
    qs = {n: matrix_to_quat(torch.from_numpy(rotations(T, seed=10 + i))).numpy() for i, n in enumerate(names)}
    for f in range(T):
        lines.append(str(f + 1))
        for n in names:
            vals = list(qs[n][f]) + list(rng.normal(size=3) + [0, 0, 9.81])
            lines.append(n + "\t" + "\t".join(f"{v:.9f}" for v in vals))
    path.write_text("\n".join(lines) + "\n")


def _write_empose(path: Path, F: int = 20) -> None:
    rng = np.random.default_rng(4)
    ori = np.stack([rotations(F, seed=20 + i) for i in range(12)], axis=1)
    mask = np.ones((F, 12), bool)
    mask[:10, 2] = False  # 10 of 240 sensor frames missing
    np.savez(path, id=np.array("0402_arms_M"), sensor_pos=rng.normal(scale=0.5, size=(F, 36)), sensor_oris=ori.reshape(F, 108),
             sensor_masks=mask, smpl_poses=rng.normal(scale=0.2, size=(F, 156)), smpl_shape=rng.normal(size=16),
             smpl_trans=rng.normal(size=(F, 3)))


def _run(*args: str) -> tuple[int, dict | None, str]:
    res = runner.invoke(app, ["recording", "import", *args], env={"COLUMNS": "400"})
    try:
        return res.exit_code, json.loads(res.stdout), res.output
    except ValueError:
        return res.exit_code, None, res.output


def test_help_has_an_example() -> None:
    res = runner.invoke(app, ["recording", "import", "--help"])
    assert res.exit_code == 0, res.output
    assert "Example: wearpose recording import" in res.output and "totalcapture" in res.output


def test_dip_imu_folder_keeps_layout_and_reports_validity(tmp_path: Path) -> None:
    _write_dip(tmp_path / "DIP" / "s_09" / "01.pkl")
    _write_dip(tmp_path / "DIP" / "s_10" / "01.pkl")
    code, res, out = _run("dip-imu", str(tmp_path / "DIP"), "--out", str(tmp_path / "o"), "--json")
    assert code == 0, out
    assert res["converted"] == 2 and res["failed"] == 0
    row = res["files"][0]
    assert row["frames"] == 30 and row["sensors"] == 6 and row["rate_hz"] == 60.0 and row["ground_truth"]
    assert row["valid_pct"] == round(100 * (6 * 30 - 3) / (6 * 30), 2)
    rec = load_recording(tmp_path / "o" / "s_10" / "01.npz")
    assert rec.names[0] == "left_forearm" and rec.ground_truth is not None


def test_dip_imu_options_pass_through(tmp_path: Path) -> None:
    p = tmp_path / "01.pkl"
    _write_dip(p)
    code, res, out = _run("dip-imu", str(p), "--out", str(tmp_path / "o"), "--sensors", "all", "--fps", "30",
                          "--no-ground-truth", "--json")
    assert code == 0, out
    row = res["files"][0]
    assert row["sensors"] == 17 and row["rate_hz"] == 30.0 and not row["ground_truth"]
    assert load_recording(tmp_path / "o" / "01.npz").sensor("head").timestamps[1] == np.float64(1 / 30)


def test_totalcapture_subset_and_human_table(tmp_path: Path) -> None:
    p = tmp_path / "s1_acting1_Xsens.sensors"
    _write_tc(p)
    code, res, out = _run("totalcapture", str(p), "--out", str(tmp_path / "o"), "--sensors", "Head,Pelvis", "--json")
    assert code == 0, out
    assert res["files"][0]["sensor_names"] == ["head", "pelvis"] and res["files"][0]["frames"] == 12
    assert load_recording(tmp_path / "o" / "s1_acting1_Xsens.npz").names == ("head", "pelvis")
    code, _, out = _run("totalcapture", str(p), "--out", str(tmp_path / "o2"))
    assert code == 0 and "1 converted, 0 failed" in out


def test_empose(tmp_path: Path) -> None:
    p = tmp_path / "0402_arms_M_clean.npz"
    _write_empose(p)
    code, res, out = _run("empose", str(p), "--out", str(tmp_path / "o"), "--sensors", "six", "--json")
    assert code == 0, out
    row = res["files"][0]
    assert row["sensors"] == 6 and row["frames"] == 20 and row["rate_hz"] == 30.0 and row["kinds"] == ["em6dof"]
    assert row["valid_pct"] == round(100 * (6 * 20 - 10) / (6 * 20), 2)  # sensor 2 (right wrist) is in the six
    assert load_recording(tmp_path / "o" / "0402_arms_M_clean.npz").ground_truth.num_frames == 20


def test_bad_file_is_named_exit_1_others_converted(tmp_path: Path) -> None:
    good, bad = tmp_path / "in" / "a_Xsens.sensors", tmp_path / "in" / "b_Xsens.sensors"
    good.parent.mkdir()
    _write_tc(good)
    _write_tc(bad)
    bad.write_text("\n".join(bad.read_text().splitlines()[:-4]) + "\n")  # truncated
    code, res, out = _run("totalcapture", str(tmp_path / "in"), "--out", str(tmp_path / "o"), "--json")
    assert code == 1
    assert res["converted"] == 1 and res["failed"] == 1
    err = [r for r in res["files"] if not r["ok"]][0]["error"]
    assert str(bad) in err and "truncated" in err
    res2 = runner.invoke(app, ["recording", "import", "totalcapture", str(bad), "--out", str(tmp_path / "o")],
                         env={"COLUMNS": "400"})
    assert res2.exit_code == 1
    assert "failed" in res2.output and "b_Xsens.sensors" in res2.output and "Traceback" not in res2.output


def test_bad_options_and_no_files(tmp_path: Path) -> None:
    p = tmp_path / "01.pkl"
    _write_dip(p)
    assert _run("vicon", str(p))[0] == 2
    assert _run("dip-imu", str(p), "--sensors", "3,99")[0] == 2
    code, _, out = _run("empose", str(tmp_path), "--out", str(tmp_path / "o"))
    assert code == 1 and "no EM-POSE" in out


def test_out_given_as_a_file_name_is_refused_naming_the_fix(tmp_path: Path) -> None:
    p = tmp_path / "01.pkl"
    _write_dip(p)
    code, _, out = _run("dip-imu", str(p), "--out", str(tmp_path / "trial.npz"))
    assert code == 2
    assert "--out" in out and "folder" in out and "trial" in out
    assert not (tmp_path / "trial.npz").exists()  # used to become a folder of that name
    (tmp_path / "taken").write_text("x")
    code, _, out = _run("dip-imu", str(p), "--out", str(tmp_path / "taken"))
    assert code == 2 and "folder" in out

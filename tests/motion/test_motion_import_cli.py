"""``wearpose motion import`` and ``wearpose data prepare`` on a user folder with one bad file."""

from __future__ import annotations

import json

import pytest
import torch
from typer.testing import CliRunner

from wearpose.cli import app
from wearpose.motion import CorpusStore, prepare_corpus, template_rest_joints
from import_testutils import BIPED_NAMES, custom_bvh_text, custom_skeleton_motion, joint_tree_to_asf_amc
from motion_testutils import synthetic_smpl_motion

REST = template_rest_joints()
runner = CliRunner()


@pytest.fixture(scope="module")
def user_folder(tmp_path_factory) -> object:
    src = tmp_path_factory.mktemp("mocap")
    local, pelvis = synthetic_smpl_motion(REST, T=20, seed=1)
    sk = custom_skeleton_motion(local, pelvis, REST, scale=1000.0, z_up=True)
    text = custom_bvh_text(sk)
    (src / "actor1").mkdir()
    (src / "actor1" / "walk.bvh").write_text(text)
    asf, amc, _ = joint_tree_to_asf_amc(sk, BIPED_NAMES, seed=2)
    (src / "actor2").mkdir()
    (src / "actor2" / "actor2.asf").write_text(asf)
    (src / "actor2" / "actor2_01.amc").write_text(amc)
    (src / "actor2" / "broken.bvh").write_text(text.replace("CHANNELS 3", "CHANNELS 4", 1))
    return src


def test_motion_import_cli(tmp_path, user_folder) -> None:
    res = runner.invoke(app, ["motion", "import", str(user_folder), "--out", str(tmp_path / "out"), "--fps", "30", "--json"])
    assert res.exit_code == 1, res.output  # one file failed
    out = json.loads(res.stdout)
    assert out["converted"] == 2 and out["failed"] == 1
    bad = [r for r in out["files"] if not r["ok"]][0]
    assert bad["file"].endswith("broken.bvh") and "broken.bvh" in bad["error"] and "line" in bad["error"]
    good = {r["file"].rsplit("/", 1)[-1]: r for r in out["files"] if r["ok"]}
    assert good["walk.bvh"]["units"]["name"] == "mm" and good["actor2_01.amc"]["fps"] == 30
    assert (tmp_path / "out" / "actor1" / "walk.npz").is_file()
    human = runner.invoke(app, ["motion", "import", str(user_folder / "actor1"), "--out", str(tmp_path / "o2")])
    assert human.exit_code == 0 and "joint map of walk.bvh" in human.stdout and "Bip01" in human.stdout
    assert runner.invoke(app, ["motion", "import", "--help"]).exit_code == 0
    (tmp_path / "empty").mkdir()
    assert runner.invoke(app, ["motion", "import", str(tmp_path / "empty")]).exit_code == 1


def test_prepare_user_folder(tmp_path, user_folder) -> None:
    res = prepare_corpus([user_folder], tmp_path / "store", workers=1, progress=False, rest_joints=REST)
    assert res["converted"] == 2 and res["failed"] == 1
    assert any("broken.bvh" in v for v in res["failures"].values())
    store = CorpusStore(tmp_path / "store")
    seq = store.load(store.clips()[0])
    assert seq.meta["import"]["up"]["axis"] == "z" and seq.pose.dtype == torch.float32


def test_motion_import_cli_asf_option_and_bone_check(tmp_path) -> None:
    """--asf picks one of several ASF files; the report shows each bone worst first and the
    warnings of a map that leaves a spine joint out."""
    from import_testutils import cmu_layout_asf_amc, cmu_layout_motion

    local, pelvis = synthetic_smpl_motion(REST, T=12, seed=4)
    asf, amc = cmu_layout_asf_amc(cmu_layout_motion(local, pelvis, REST))
    src = tmp_path / "amc"
    src.mkdir()
    (src / "a.asf").write_text(asf)
    (src / "b.asf").write_text(asf)
    (src / "x_01.amc").write_text(amc)
    res = runner.invoke(app, ["motion", "import", str(src), "--out", str(tmp_path / "o1")])
    assert res.exit_code == 1 and "--asf" in res.output
    res = runner.invoke(app, ["motion", "import", str(src), "--out", str(tmp_path / "o2"), "--asf", str(src / "a.asf")])
    assert res.exit_code == 0, res.output
    assert "bone check of x_01.amc" in res.stdout and "lowerback->upperback" in res.stdout and "warning" not in res.output
    jm = tmp_path / "old.yaml"
    jm.write_text("spine1: upperback\nspine2: null\n")
    res = runner.invoke(app, ["motion", "import", str(src / "x_01.amc"), "--out", str(tmp_path / "o3"),
                              "--asf", str(src / "b.asf"), "--joint-map", str(jm), "--json"])
    assert res.exit_code == 0, res.output
    row = json.loads(res.stdout)["files"][0]
    assert row["bone_error_deg"]["ranked"][0]["bone"] == "pelvis->spine1" and "pelvis->spine1" in row["warnings"][0]
    bad = runner.invoke(app, ["motion", "import", str(src), "--asf", str(src / "nope.asf")])
    assert bad.exit_code != 0 and "nope.asf" in bad.output

"""Bring-your-own-motion import: skeleton maps, units, up axis, rest pose, errors, folders."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from wearpose.body.kinematics import forward_kinematics
from wearpose.body.skeleton import JOINT_NAMES
from wearpose.errors import InputFileError, WearposeError
from wearpose.export import write_smpl_bvh
from wearpose.geometry import geodesic_angle
from wearpose.motion import MotionSequence, read_bvh, template_rest_joints
from wearpose.motion.importer import UP_AXES, detect_units, detect_up, import_motion, import_paths, parse_units
from wearpose.motion.mapping import CMU_ASF, MIXAMO, RIGIFY, auto_map, builtin_match, split_name
from wearpose.motion.retarget import BUILTIN_MAPS
from import_testutils import (
    BIPED_NAMES, cmu_layout_asf_amc, cmu_layout_motion, custom_bvh_text, custom_skeleton_motion, joint_tree_to_asf_amc,
)
from motion_testutils import corpus_dir, synthetic_smpl_motion

REST = template_rest_joints()


@pytest.fixture(scope="module")
def smpl_motion() -> tuple[torch.Tensor, torch.Tensor]:
    return synthetic_smpl_motion(REST, T=40, seed=0)


@pytest.fixture(scope="module")
def biped(smpl_motion) -> dict:
    """The acceptance skeleton: renamed joints, A-pose rest, millimetres, Z up."""
    return custom_skeleton_motion(*smpl_motion, REST, scale=1000.0, z_up=True)


def _source_error_deg(imp, sk: dict) -> float:
    """Mean angle (deg) between each retargeted SMPL bone and the true source bone (the known
    motion the file was written from), over bones and frames."""
    _, J = forward_kinematics(imp.sequence.pose.double(), REST)
    names = sk["names"]
    errs = []
    for k, n in enumerate(names):
        p = sk["parents"][k]
        if p < 0 or n in ("spine2",):
            continue
        a, b = JOINT_NAMES.index(names[p]), JOINT_NAMES.index(n)
        ds = J[:, b] - J[:, a]
        dt = sk["smpl_pos"][:, k] - sk["smpl_pos"][:, p]
        cos = (ds * dt).sum(-1) / ds.norm(dim=-1) / dt.norm(dim=-1)
        errs.append(torch.rad2deg(torch.arccos(cos.clamp(-1, 1))).mean())
    return float(torch.stack(errs).mean())


def test_biped_apose_mm_zup_bvh(tmp_path, biped) -> None:
    path = tmp_path / "biped.bvh"
    path.write_text(custom_bvh_text(biped))
    imp = import_motion(path, REST)
    r = imp.report
    assert r.map_source == "automatic"
    table = {row[0]: row[1] for row in r.mapping}
    for smpl, name in BIPED_NAMES.items():
        assert table[smpl] == name, (smpl, table[smpl])
    assert r.units["name"] == "mm" and r.up["axis"] == "z" and r.rest_pose["kind"] == "A-pose"
    assert 40 < r.rest_pose["bone_deg"]["left_shoulder"] < 50
    assert r.bone_error_deg["mean"] < 10.0 and _source_error_deg(imp, biped) < 10.0
    # The pelvis lands where the source pelvis is (metres, Y up), scaled by the leg ratio 1.
    assert r.translation_scale == pytest.approx(1.0, abs=1e-4)
    pelvis = imp.sequence.trans.double() + REST[0]
    assert torch.allclose(pelvis, biped["smpl_pos"][:, 0], atol=2e-3)


@pytest.mark.parametrize("fmt", ["bvh", "asf"])
def test_apose_rig_gives_back_the_smpl_pose_parameters(tmp_path, smpl_motion, biped, fmt: str) -> None:
    """Rest-pose correction keeps SMPL pose parameters meaningful: the A-pose, Z-up, mm rig
    written from known SMPL motion imports (on the same rest skeleton) to the same local
    rotations, joint by joint (hands excepted: the rig has none)."""
    if fmt == "bvh":
        (tmp_path / "a.bvh").write_text(custom_bvh_text(biped))
        imp = import_motion(tmp_path / "a.bvh", REST)
    else:
        asf, amc, _ = joint_tree_to_asf_amc(biped, BIPED_NAMES, seed=7)
        (tmp_path / "a.asf").write_text(asf)
        (tmp_path / "a_01.amc").write_text(amc)
        imp = import_motion(tmp_path / "a_01.amc", REST)
    local, _ = smpl_motion
    err = torch.rad2deg(geodesic_angle(imp.sequence.pose.double(), local)).amax(0)
    worst = {n: round(float(e), 4) for n, e in zip(JOINT_NAMES, err) if e > 0.01 and "hand" not in n}
    assert not worst, worst


def test_biped_apose_mm_zup_asf_amc(tmp_path, biped) -> None:
    """The same skeleton as ASF/AMC, mm values under ':units length 1' (declared inches: the leg
    would be 20 m, so the unit is detected)."""
    asf, amc, _ = joint_tree_to_asf_amc(biped, BIPED_NAMES, length_mult=1.0, seed=4)
    (tmp_path / "biped.asf").write_text(asf)
    (tmp_path / "biped_01.amc").write_text(amc)
    imp = import_motion(tmp_path / "biped_01.amc", REST, fps=30)
    r = imp.report
    assert r.format == "asf/amc" and r.units["name"] == "mm" and "implausible" in r.units["how"]
    assert r.up["axis"] == "z" and r.fps == 30
    err = _source_error_deg(imp, biped)
    assert r.bone_error_deg["mean"] < 10.0 and err < 10.0, (r.bone_error_deg, err)


@pytest.mark.parametrize("axis", ["y", "-z", "x"])
def test_up_axis_detected(tmp_path, smpl_motion, axis: str) -> None:
    sk = custom_skeleton_motion(*smpl_motion, REST, scale=100.0, world=UP_AXES[axis].T)
    (tmp_path / "a.bvh").write_text(custom_bvh_text(sk))
    imp = import_motion(tmp_path / "a.bvh", REST)
    assert imp.report.up["axis"] == axis and imp.report.units["name"] == "cm"
    assert _source_error_deg(imp, sk) < 1.0


def test_overrides_and_joint_map(tmp_path, biped) -> None:
    (tmp_path / "b.bvh").write_text(custom_bvh_text(biped))
    jm = tmp_path / "map.yaml"
    jm.write_text("left_foot: null\nright_foot: null\nneck: Bip01 Neck\nunits: mm\nup: z\n")
    imp = import_motion(tmp_path / "b.bvh", REST, joint_map=jm)
    r = imp.report
    assert r.units["how"] == "given" and r.up["how"] == "given" and "joint map" in r.map_source
    table = {row[0]: row for row in r.mapping}
    assert table["left_foot"][1] == "-" and table["neck"][2] == "joint map"
    # A wrong override is not silently accepted: inches make a 20 m person, yet the result is
    # still a clean retarget (units only scale the root) -- the report says what was used.
    imp2 = import_motion(tmp_path / "b.bvh", REST, units="inch", up="z")
    assert imp2.report.units["leg_m"] > 15
    bad = tmp_path / "bad.yaml"
    bad.write_text("left_thigh: Bip01 L Thigh\n")
    with pytest.raises(InputFileError, match="unknown key 'left_thigh'"):
        import_motion(tmp_path / "b.bvh", REST, joint_map=bad)
    bad.write_text("left_hip: Bip01 L Thighs\n")
    with pytest.raises(InputFileError, match="Thighs") as ei:
        import_motion(tmp_path / "b.bvh", REST, joint_map=bad)
    assert "b.bvh" in str(ei.value)
    with pytest.raises(WearposeError, match="furlong"):
        import_motion(tmp_path / "b.bvh", REST, units="furlong")


def test_smpl_export_reimports_to_the_same_joints(tmp_path, smpl_motion) -> None:
    local, pelvis = smpl_motion
    seq = MotionSequence(local.float(), torch.zeros(10), (pelvis - REST[0]).float(), 30.0)
    write_smpl_bvh(seq, tmp_path / "ours.bvh", REST)
    imp = import_motion(tmp_path / "ours.bvh", REST)
    _, J0 = forward_kinematics(seq.pose.double(), REST)
    _, J1 = forward_kinematics(imp.sequence.pose.double(), REST)
    J0 = J0 + seq.trans.double()[:, None]
    J1 = J1 + imp.sequence.trans.double()[:, None]
    assert float((J0 - J1).norm(dim=-1).max()) < 1e-3
    assert imp.report.skeleton == "smpl" and imp.report.frames == 40


def test_builtin_naming_schemes() -> None:
    from wearpose.motion.bvh import BvhSkeleton

    def skel(names: list[str]) -> BvhSkeleton:
        return BvhSkeleton(tuple(names), tuple([-1] + [0] * (len(names) - 1)), np.zeros((len(names), 3)), tuple(() for _ in names))

    mix = ["mixamorig:" + n for n in MIXAMO.joints.values() if "Middle" not in n]
    assert builtin_match(skel(mix)).name == "mixamo"
    assert builtin_match(skel(["DEF-" + n for n in RIGIFY.joints.values()])).name == "rigify"
    assert builtin_match(skel(list(CMU_ASF.joints.values()))).name == "cmu_asf"
    assert builtin_match(skel(["Hips", "Spine"])) is None
    assert split_name("mixamorig:LeftUpLeg") == ("left", "upleg")
    assert split_name("thigh.L") == ("left", "thigh")
    assert split_name("Bip01 R Calf") == ("right", "calf")
    assert split_name("lfemur") == ("left", "femur") and split_name("lowerback") == (None, "lowerback")


def test_mixamo_bvh_retargets(tmp_path, smpl_motion) -> None:
    """SMPL tree written with Mixamo names (no fingers) in cm, Y up: the built-in map is used."""
    sk = custom_skeleton_motion(*smpl_motion, REST, scale=100.0, z_up=False, arm_down_deg=0.0)
    names = {s: "mixamorig:" + n for s, n in MIXAMO.joints.items()}
    (tmp_path / "m.bvh").write_text(custom_bvh_text(sk, names))
    imp = import_motion(tmp_path / "m.bvh", REST)
    assert imp.report.map_source == "built-in mixamo" and imp.report.rest_pose["kind"] == "T-pose"
    assert _source_error_deg(imp, sk) < 1.0


def test_units_rule() -> None:
    assert detect_units(82.0)["name"] == "cm"
    assert detect_units(820.0)["name"] == "mm"
    assert detect_units(0.82)["name"] == "m"
    assert detect_units(32.0)["name"] == "inch"
    assert detect_units(14.5)["name"] == "acclaim"
    assert detect_units(14.5, ("acclaim", 0.0254 / 0.45))["how"] == "declared"
    assert parse_units("centimetres") == ("cm", 0.01) and parse_units(0.5)[1] == 0.5


def test_malformed_files_name_the_problem(tmp_path, biped) -> None:
    text = custom_bvh_text(biped)
    lines = text.splitlines()
    (tmp_path / "trunc.bvh").write_text("\n".join(lines[:-3]) + "\n")
    with pytest.raises(InputFileError, match=r"trunc\.bvh.*truncated motion"):
        import_motion(tmp_path / "trunc.bvh", REST)
    bad = list(lines)
    bad[-1] = bad[-1] + " 0.0"
    (tmp_path / "chan.bvh").write_text("\n".join(bad) + "\n")
    with pytest.raises(InputFileError, match=rf"chan\.bvh \[line {len(lines)}\].*values"):
        import_motion(tmp_path / "chan.bvh", REST)
    # Missing joint: no left leg names -> the error names the missing SMPL joint.
    (tmp_path / "noleg.bvh").write_text(text.replace("Bip01 L Thigh", "Bip01 Thing").replace("Bip01 L Calf", "Bip01 Thang"))
    with pytest.raises(InputFileError, match=r"noleg\.bvh \[joint \w+\]: no joint found for SMPL .*left_hip"):
        import_motion(tmp_path / "noleg.bvh", REST)
    asf, amc, _ = joint_tree_to_asf_amc(biped, BIPED_NAMES, seed=1)
    (tmp_path / "u.asf").write_text(asf.replace("length 1", "length one"))
    (tmp_path / "u_01.amc").write_text(amc)
    with pytest.raises(InputFileError, match=r"u\.asf \[line 5\]"):
        import_motion(tmp_path / "u_01.amc", REST)


def test_folder_with_one_bad_file(tmp_path, biped) -> None:
    src = tmp_path / "in"
    (src / "sub").mkdir(parents=True)
    text = custom_bvh_text(biped)
    (src / "good.bvh").write_text(text)
    asf, amc, _ = joint_tree_to_asf_amc(biped, BIPED_NAMES, seed=1)
    (src / "sub" / "s.asf").write_text(asf)
    (src / "sub" / "s_01.amc").write_text(amc)
    (src / "broken.bvh").write_text(text[: len(text) // 2])
    res = import_paths([src], tmp_path / "out", REST)
    assert res["converted"] == 2 and res["failed"] == 1
    failed = [r for r in res["files"] if not r["ok"]]
    assert failed[0]["file"].endswith("broken.bvh") and "broken.bvh" in failed[0]["error"]
    assert (tmp_path / "out" / "good.npz").is_file() and (tmp_path / "out" / "sub" / "s_01.npz").is_file()
    seq = MotionSequence.load(tmp_path / "out" / "good.npz")
    assert seq.meta["import"]["units"]["name"] == "mm" and seq.num_frames == 40


@pytest.mark.corpus
def test_corpus_skeletons_bone_directions() -> None:
    """Every corpus skeleton (one clip each): bone directions within 10 deg of the source."""
    data = corpus_dir()
    if data is None:
        pytest.skip("corpus not found")
    for rel, name in (("cmu_daz/05/05_01.bvh.gz", "cmu_daz"), ("bandai/bandai-B/dataset-2_walk_feminine_001.bvh.gz", "bandai")):
        imp = import_motion(data / rel, REST)
        r = imp.report
        assert r.skeleton == name and r.units["name"] == "cm" and r.up["axis"] == "y"
        assert r.bone_error_deg["mean"] < 10.0 and math.isfinite(r.bone_error_deg["mean"])
        # The declared Y-up agrees with what detection finds in the clip, and the automatic
        # match alone finds the same joints as the built-in map.
        motion = read_bvh(data / rel)
        assert detect_up(motion, imp.retargeted.smap)["axis"] == "y"
        joints, _, _ = auto_map(motion.skeleton, motion.translations[0].numpy())
        assert joints == dict(BUILTIN_MAPS[name].joints)
        # A partial joint map keeps the built-in map's measured constants for untouched joints.
        part = import_motion(data / rel, REST, joint_map={"joints": {"left_foot": None}}).report
        assert part.map_source == f"built-in {name} + joint map" and set(part.hinge_axes.values()) == {"map"}


def _scheme(trunk: tuple[str, ...], left: tuple[str, ...], right: tuple[str, ...]) -> dict[str, str]:
    """SMPL joint -> name for a rig: trunk = pelvis, spine1, spine2, spine3, neck, head; sides =
    hip, knee, ankle, foot, collar, shoulder, elbow, wrist."""
    limbs = ("hip", "knee", "ankle", "foot", "collar", "shoulder", "elbow", "wrist")
    out = dict(zip(("pelvis", "spine1", "spine2", "spine3", "neck", "head"), trunk))
    out.update({f"left_{k}": v for k, v in zip(limbs, left)})
    out.update({f"right_{k}": v for k, v in zip(limbs, right)})
    return out


RIG_SCHEMES = {
    "unreal": _scheme(("pelvis", "spine_01", "spine_02", "spine_03", "neck_01", "head"),
                      ("thigh_l", "calf_l", "foot_l", "ball_l", "clavicle_l", "upperarm_l", "lowerarm_l", "hand_l"),
                      ("thigh_r", "calf_r", "foot_r", "ball_r", "clavicle_r", "upperarm_r", "lowerarm_r", "hand_r")),
    "optitrack": _scheme(("Hip", "Ab", "Chest2", "Chest", "Neck", "Head"),
                         ("LThigh", "LShin", "LFoot", "LToe", "LShoulder", "LUArm", "LFArm", "LHand"),
                         ("RThigh", "RShin", "RFoot", "RToe", "RShoulder", "RUArm", "RFArm", "RHand")),
    "xsens": _scheme(("Pelvis", "L5", "L3", "T8", "Neck", "Head"),
                     ("LeftUpperLeg", "LeftLowerLeg", "LeftFoot", "LeftToe", "LeftShoulder", "LeftUpperArm", "LeftForeArm", "LeftHand"),
                     ("RightUpperLeg", "RightLowerLeg", "RightFoot", "RightToe", "RightShoulder", "RightUpperArm", "RightForeArm", "RightHand")),
    "rokoko": _scheme(("Hips", "Spine1", "Spine2", "Spine4", "Neck", "Head"),
                      ("LeftThigh", "LeftShin", "LeftFoot", "LeftToe", "LeftShoulder", "LeftArm", "LeftForeArm", "LeftHand"),
                      ("RightThigh", "RightShin", "RightFoot", "RightToe", "RightShoulder", "RightArm", "RightForeArm", "RightHand")),
}


@pytest.mark.parametrize("scheme", sorted(RIG_SCHEMES))
def test_common_rig_names_match_automatically(tmp_path, scheme: str) -> None:
    local, pelvis = synthetic_smpl_motion(REST, T=8, seed=2)
    sk = custom_skeleton_motion(local, pelvis, REST, scale=100.0, z_up=False, arm_down_deg=0.0)
    names = RIG_SCHEMES[scheme]
    (tmp_path / "r.bvh").write_text(custom_bvh_text(sk, names))
    r = import_motion(tmp_path / "r.bvh", REST).report
    got = {row[0]: row[1] for row in r.mapping if row[1] != "-"}
    assert got == names, {k: (got.get(k), v) for k, v in names.items() if got.get(k) != v}
    assert r.bone_error_deg["mean"] < 1e-3


def test_auto_map_skips_helpers_fingers_and_links() -> None:
    """Twist bones (with length), fingers, an end joint and zero-length links do not fool it."""
    from wearpose.motion.bvh import BvhSkeleton
    from wearpose.motion.mapping import auto_map

    tree = [  # name, parent, offset (cm, Y up)
        ("root", None, (0, 0, 0)), ("pelvis", "root", (0, 95, 0)),
        ("spine_01", "pelvis", (0, 10, 0)), ("spine_02", "spine_01", (0, 12, 0)), ("spine_03", "spine_02", (0, 12, 0)),
        ("neck_01", "spine_03", (0, 20, 0)), ("head", "neck_01", (0, 10, 0)), ("HeadTop_End", "head", (0, 18, 0)),
    ]
    for s, x in (("l", 1), ("r", -1)):
        tree += [
            (f"hip_link_{s}", "pelvis", (0, 0, 0)), (f"thigh_{s}", f"hip_link_{s}", (9 * x, -5, 0)),
            (f"thigh_twist_01_{s}", f"thigh_{s}", (0, -20, 0)), (f"calf_{s}", f"thigh_{s}", (0, -40, 0)),
            (f"calf_twist_01_{s}", f"calf_{s}", (0, -20, 0)), (f"foot_{s}", f"calf_{s}", (0, -42, 0)),
            (f"ball_{s}", f"foot_{s}", (0, -6, 12)),
            (f"clavicle_{s}", "spine_03", (3 * x, 15, 0)), (f"upperarm_{s}", f"clavicle_{s}", (15 * x, 0, 0)),
            (f"upperarm_twist_01_{s}", f"upperarm_{s}", (14 * x, 0, 0)), (f"lowerarm_{s}", f"upperarm_{s}", (28 * x, 0, 0)),
            (f"hand_{s}", f"lowerarm_{s}", (25 * x, 0, 0)),
            *[(f"{f}_01_{s}", f"hand_{s}", (8 * x, 0, k)) for k, f in enumerate(("thumb", "index", "middle", "ring", "pinky"))],
        ]
    names = [t[0] for t in tree]
    skel = BvhSkeleton(tuple(names), tuple(-1 if p is None else names.index(p) for _, p, _ in tree),
                       np.array([t[2] for t in tree], dtype=float), tuple(() for _ in tree))
    joints, how, _ = auto_map(skel, skel.offsets)
    want = RIG_SCHEMES["unreal"]
    assert {k: v for k, v in joints.items()} == want, {k: (joints.get(k), v) for k, v in want.items() if joints.get(k) != v}


@pytest.fixture(scope="module")
def cmu_layout(smpl_motion) -> dict:
    """Known motion on CMU's real ASF layout: collars from the thorax end, lowerback from the
    root, root tilted 30-40 deg against lowerback, a bending upperneck, twisting lwrist."""
    return cmu_layout_motion(*smpl_motion, REST)


def _write_cmu(tmp_path, cmu: dict) -> object:
    asf, amc = cmu_layout_asf_amc(cmu, seed=3)
    (tmp_path / "86.asf").write_text(asf)
    (tmp_path / "86_01.amc").write_text(amc)
    return tmp_path / "86_01.amc"


def _bone_errors_vs_truth(imp, cmu: dict) -> dict[str, float]:
    """Per mapped bone, the largest angle (deg, over frames) between the SMPL bone and the true
    source bone (the known motion the file was written from); zero-length source bones skipped."""
    from wearpose.body.skeleton import JOINT_INDEX
    from wearpose.motion.retarget import bone_pairs

    _, J = forward_kinematics(imp.sequence.pose.double(), REST)
    smap = imp.retargeted.smap.joints
    start = {**cmu["start"], "root": cmu["root_pos"]}
    out = {}
    for a, b in bone_pairs(smap) + (("right_hip", "left_hip"),):
        src = start[smap[b]] - start[smap[a]]
        if float(src.norm(dim=-1).max()) < 1e-9:
            continue
        ds = J[:, JOINT_INDEX[b]] - J[:, JOINT_INDEX[a]]
        cos = (ds * src).sum(-1) / ds.norm(dim=-1) / src.norm(dim=-1)
        out[f"{a}->{b}"] = float(torch.rad2deg(torch.arccos(cos.clamp(-1, 1))).max())
    return out


def test_cmu_layout_asf_amc_imports_without_a_joint_map(tmp_path, cmu_layout) -> None:
    """Acceptance (issue 23): CMU's real layout imports with the built-in map and every mapped
    bone (spine segments, neck, collars, limbs, the hip line) within 10 deg of the source at
    every frame (measured: < 1e-5 deg)."""
    tilt = cmu_layout["root_vs_lowerback_deg"]
    assert 29.9 < float(tilt.min()) and float(tilt.max()) < 40.1
    imp = import_motion(_write_cmu(tmp_path, cmu_layout), REST)
    r = imp.report
    assert r.map_source == "built-in cmu_asf" and r.units["name"] == "acclaim" and r.up["axis"] == "y"
    table = {row[0]: row[1] for row in r.mapping}
    assert (table["pelvis"], table["spine1"], table["spine2"], table["spine3"]) == ("root", "lowerback", "upperback", "thorax")
    # The chest's twist comes from the shoulders (the clavicles start at one point); the neck
    # bone spans upperneck, which the map leaves out, so it is swung onto the source bone.
    meta = imp.sequence.meta["retarget"]
    assert meta["twist_refs"]["spine3"] == "left_shoulder-right_shoulder"
    assert "neck" in meta["bone_swing_fixed"] and "pelvis" not in meta["bone_swing_fixed"]
    errs = _bone_errors_vs_truth(imp, cmu_layout)
    assert {"spine1->spine2", "spine2->spine3", "spine3->neck", "neck->head", "left_collar->left_shoulder",
            "right_hip->left_hip"} <= set(errs)
    worst = max(errs, key=errs.get)
    assert errs[worst] < 10.0, (worst, errs[worst])
    assert errs[worst] < 1e-3, (worst, errs[worst])  # exact up to float rounding
    # The report: every mapped bone, worst first, no warning.
    ranked = r.bone_error_deg["ranked"]
    assert [row["max"] for row in ranked] == sorted((row["max"] for row in ranked), reverse=True)
    assert len(ranked) == 18 and r.bone_error_deg["worst_bone_max"] < 1e-3 and not r.warnings


def test_bone_warnings_name_the_worst_bone(tmp_path, cmu_layout) -> None:
    """A map that leaves lowerback out (spine1 = upperback, the old built-in map) loses the
    root's 30-40 deg tilt in the pelvis -> spine1 bone: the report ranks it first and warns."""
    amc = _write_cmu(tmp_path, cmu_layout)
    imp = import_motion(amc, REST, joint_map={"joints": {"spine1": "upperback", "spine2": None}})
    be = imp.report.bone_error_deg
    assert be["ranked"][0]["bone"] == "pelvis->spine1" and be["ranked"][0]["source"] == "root->upperback"
    assert 25.0 < be["worst_bone_max"] < 45.0 and be["per_bone"]["pelvis->spine1"] > 20.0
    assert len(imp.report.warnings) == 1 and "pelvis->spine1" in imp.report.warnings[0]
    assert "--joint-map" in imp.report.warnings[0] and "root->upperback" in imp.report.warnings[0]


def test_asf_option_picks_the_skeleton(tmp_path, cmu_layout) -> None:
    """A folder with several actors' ASF files: the AMC fails without asf=, names the way out,
    and imports with it."""
    asf, amc = cmu_layout_asf_amc(cmu_layout, seed=3)
    (tmp_path / "actorA.asf").write_text(asf)
    (tmp_path / "actorB.asf").write_text(asf)
    (tmp_path / "take_01.amc").write_text(amc)
    with pytest.raises(InputFileError, match="2 .asf files beside it") as ei:
        import_motion(tmp_path / "take_01.amc", REST)
    assert "--asf" in ei.value.expected
    imp = import_motion(tmp_path / "take_01.amc", REST, asf=tmp_path / "actorB.asf")
    assert imp.report.skeleton == "cmu_asf" and imp.sequence.num_frames == 40
    with pytest.raises(InputFileError, match="not found"):
        import_motion(tmp_path / "take_01.amc", REST, asf=tmp_path / "nope.asf")

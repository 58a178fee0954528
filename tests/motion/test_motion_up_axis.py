"""The import's up-axis detector on clips that lie down or stay on the floor (issue 23): built
here from known SMPL motion, written as a renamed skeleton in worlds with different up axes."""

from __future__ import annotations

import math

import pytest
import torch

from wearpose.body.skeleton import JOINT_INDEX
from wearpose.geometry import rotation_x, rotation_z
from wearpose.motion import template_rest_joints
from wearpose.motion.importer import UP_AXES, import_motion
from import_testutils import custom_bvh_text, custom_skeleton_motion

REST = template_rest_joints()


def _smooth(T: int, a: int, b: int) -> torch.Tensor:
    """0 before frame a, 1 after frame b, a cosine ramp between."""
    t = ((torch.arange(T, dtype=torch.float64) - a) / max(b - a, 1)).clamp(0, 1)
    return 0.5 - 0.5 * torch.cos(math.pi * t)


def lying_down_motion(T: int = 120) -> tuple[torch.Tensor, torch.Tensor]:
    """Standing still for 20 frames, falling backwards stiffly about the ankles onto the back
    (frames 20-40), then lying for 80 frames waving the arms. SMPL local rotations and pelvis
    positions (m, Y up)."""
    local = torch.eye(3, dtype=torch.float64).repeat(T, 24, 1, 1)
    tilt = -0.5 * math.pi * _smooth(T, 20, 40)
    root = rotation_x(tilt)  # -90 deg about x: head to -z, face up
    local[:, 0] = root
    wave = 0.6 * torch.sin(torch.linspace(0, 6 * math.pi, T, dtype=torch.float64))
    for side, s in (("left_shoulder", 1.0), ("right_shoulder", -1.0)):
        local[:, JOINT_INDEX[side]] = rotation_z(s * wave * _smooth(T, 40, 50))
    ankles = 0.5 * (REST[JOINT_INDEX["left_ankle"]] + REST[JOINT_INDEX["right_ankle"]]).double()
    pivot = torch.tensor([0.0, 0.08, 0.0], dtype=torch.float64)
    pelvis = pivot - (root @ (ankles - REST[0].double()))  # the ankles stay on the floor
    return local, pelvis


def sit_up_motion(T: int = 150) -> tuple[torch.Tensor, torch.Tensor]:
    """A floor exercise: lying on the back, three sit-ups (trunk raised 0-75 deg), the legs flat
    on the floor throughout."""
    local = torch.eye(3, dtype=torch.float64).repeat(T, 24, 1, 1)
    phase = torch.linspace(0, 3 * 2 * math.pi, T, dtype=torch.float64)
    lift = math.radians(75) * 0.5 * (1 - torch.cos(phase))
    root = rotation_x(-0.5 * math.pi + lift)
    flat = rotation_x(torch.tensor(-0.5 * math.pi, dtype=torch.float64))
    local[:, 0] = root
    for hip in ("left_hip", "right_hip"):
        local[:, JOINT_INDEX[hip]] = root.transpose(-1, -2) @ flat  # legs keep lying flat
    pelvis = torch.tensor([0.0, 0.1, 0.0], dtype=torch.float64).repeat(T, 1)
    return local, pelvis


def get_up_motion() -> tuple[torch.Tensor, torch.Tensor]:
    """A floor clip: two sit-ups lying on the back, then rising stiffly about the ankles to stand
    (the lying-down clip played backwards)."""
    up_local, up_pelvis = lying_down_motion(T=60)
    rise_local, rise_pelvis = up_local.flip(0), up_pelvis.flip(0)
    sit_local, _ = sit_up_motion(T=100)
    sit_local = sit_local[:67]  # two sit-ups, ending flat on the back
    sit_pelvis = rise_pelvis[:1].repeat(sit_local.shape[0], 1)
    return torch.cat([sit_local, rise_local]), torch.cat([sit_pelvis, rise_pelvis])


def _import(tmp_path, motion: tuple[torch.Tensor, torch.Tensor], axis: str, up: str | None = None):
    sk = custom_skeleton_motion(*motion, REST, scale=100.0, world=UP_AXES[axis].T)
    f = tmp_path / f"clip_{axis.replace('-', 'm')}.bvh"
    f.write_text(custom_bvh_text(sk))
    return import_motion(f, REST, up=up).report


@pytest.mark.parametrize("axis", ["y", "z", "-x"])
def test_lying_down_clip_gets_its_up_axis_and_warns_of_the_disagreement(tmp_path, axis: str) -> None:
    r = _import(tmp_path, lying_down_motion(), axis)
    assert r.up["axis"] == axis, r.up
    ev = r.up["evidence"]
    # The old rule (the most extended frames) points along the lying body: the floor overrules it.
    assert ev["standing"]["axis"] != axis and ev["floor"]["axis"] == axis
    assert any(w.startswith("up axis: the most extended frames point along") and f"--up {ev['standing']['axis']}" in w
               for w in r.warnings), r.warnings


@pytest.mark.parametrize("axis", ["y", "-z"])
def test_floor_clip_gets_its_up_axis(tmp_path, axis: str) -> None:
    r = _import(tmp_path, get_up_motion(), axis)
    assert r.up["axis"] == axis and r.up["evidence"]["floor"]["axis"] == axis, r.up


def test_sit_ups_alone_keep_the_upright_reading_and_warn(tmp_path) -> None:
    """Sit-ups with no standing are, as motion, toe touches turned 90 deg: the floor evidence
    does not decide (no upright frame on it), the upright reading is kept and the report warns
    that it disagrees with the floor."""
    r = _import(tmp_path, sit_up_motion(), "y")
    ev = r.up["evidence"]
    assert ev["floor"]["axis"] is None and r.up["axis"] == ev["standing"]["axis"] == "-z"
    assert any(w.startswith("up axis") and "--up" in w for w in r.warnings), r.warnings


def test_up_option_overrides_the_detector(tmp_path) -> None:
    r = _import(tmp_path, lying_down_motion(), "y", up="z")
    assert r.up["axis"] == "z" and r.up["how"] == "given"
    assert not any(w.startswith("up axis") for w in r.warnings)


def test_missing_joint_error_gives_the_joint_map_lines(tmp_path) -> None:
    """A skeleton whose left leg names are not recognised: the error names the SMPL joints, the
    --joint-map lines to write and the file's joints nothing is mapped to (the candidates)."""
    sk = custom_skeleton_motion(*lying_down_motion(T=10), REST, scale=100.0, world=UP_AXES["y"].T)
    text = custom_bvh_text(sk).replace("Bip01 L Thigh", "Bip01 Thing").replace("Bip01 L Calf", "Bip01 Thang")
    (tmp_path / "noleg.bvh").write_text(text)
    from wearpose.errors import InputFileError

    with pytest.raises(InputFileError) as e:
        import_motion(tmp_path / "noleg.bvh", REST)
    msg = str(e.value)
    assert "no joint found for SMPL" in msg and "left_hip" in msg
    assert "'left_hip: <your joint>'" in msg and "joints of yours mapped to nothing yet: " in msg and "Bip01 Thing" in msg, msg

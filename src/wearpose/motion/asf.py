"""Acclaim ASF/AMC reader (skeleton file + motion file), e.g. Vicon exports and the CMU database.

References: *Acclaim Skeleton File Definition V1.10* (M. Schafer, Acclaim, 1994/95; copies at
mocap.co.nz/downloads/ASF_spec_v1.html), the CMU note *Acclaim Format - ASF line details*
(graphics.cs.cmu.edu/nsp/course/cs229/info/ACCLAIMdef.html), J. Lander's *Acclaim ASF/AMC*
(research.cs.wisc.edu/graphics/Courses/cs-838-1999/Jeff/ASF-AMC.html) and the CMU/USC mocap
player by S. Lin, A. Safonova, K. Bhat, J. Barbic and Y. Zhao (``skeleton.cpp``, the reference
implementation for the CMU database).

Semantics implemented (column vectors, a rotation maps local to parent/world):

- ``:units``: ``length L`` is a multiplier: file lengths divided by ``L`` are the "local units",
  inches in Acclaim's definition (CMU: ``length 0.45``, i.e. 1 file unit = 1/0.45 inch), so the
  declared scale is ``0.0254 / L`` metres per file unit (:attr:`AsfSkeleton.units_to_m`);
  ``angle deg|rad`` applies to ``axis``/``orientation``/``limits`` and to the AMC values (an
  AMC ``:DEGREES``/``:RADIANS`` header must agree). ``mass`` is read and ignored.
- Rotation order tokens (``axis XYZ``, ``dof rx ry rz``, root ``order``) list rotations about
  **fixed** axes in the order they are applied, so ``XYZ`` composes as ``R = Rz @ Ry @ Rx``.
- A bone's ``direction`` (unit, world frame of the base pose) and ``length`` place its end
  relative to its start; a child starts at its parent's end (the root's children start at the
  root). In the base pose every bone frame is world-aligned.
- Bone frames: ``C`` from ``axis`` (the bone's local coordinate system), ``M`` from the AMC dof
  values of that bone composed in the listed order; the bone's rotation relative to its parent,
  expressed in the world-aligned base-pose frames, is **L = C · M · C⁻¹** (Lander: ``Cinv M C B``
  in row-vector form; Barbic's player: ``rot_parent_current``). Translation dofs
  ``tx ty tz`` move the bone's start by ``C @ t``; ``l`` lengthens the bone along its
  direction.
- Root: ``order`` gives the AMC root values (translations and rotations, any interleaving) and
  the fixed-axis rotation order; ``position``/``orientation`` (``axis`` order) are pre-set
  offsets: root world rotation ``M_order @ O``, position ``position + (tx, ty, tz)``.

The result is a :class:`wearpose.motion.bvh.BvhMotion` whose joints are the root and the bones,
each joint placed at its bone's **start** (so ``lfemur`` sits at the hip, ``ltibia`` at the knee),
with the bone's end as End Site for leaves. Everything downstream (retargeting, import) treats it
like a BVH clip. AMC stores no frame rate: ``fps`` is an argument (default 120 Hz, CMU's rate)
and ``meta["fps_assumed"]`` says whether it was given.

Malformed input raises :class:`wearpose.errors.InputFileError` naming the file, the line (and
bone), the problem and the expected form.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from wearpose.errors import InputFileError
from wearpose.geometry import euler_to_matrix
from wearpose.geometry.units import INCH_TO_M
from wearpose.motion.bvh import BvhMotion, BvhSkeleton, read_text_file

#: Default AMC frame rate (the CMU database is captured at 120 Hz).
DEFAULT_AMC_FPS = 120.0
_ROT_DOFS = {"rx": "X", "ry": "Y", "rz": "Z"}
_TRANS_DOFS = {"tx": 0, "ty": 1, "tz": 2}
_DOF_FORM = "dof tokens from rx ry rz tx ty tz l"
_CHANNEL_NAME = {"rx": "Xrotation", "ry": "Yrotation", "rz": "Zrotation",
                 "tx": "Xposition", "ty": "Yposition", "tz": "Zposition", "l": "length"}


def acclaim_rotation(angles: torch.Tensor, order: str) -> torch.Tensor:
    """Rotations about fixed axes applied in ``order`` (Acclaim ``XYZ``: ``Rz @ Ry @ Rx``).

    Args:
        angles: ``(..., k)`` radians, one per letter of ``order``, in that order.
        order: axis letters, e.g. ``"XYZ"``.

    Returns:
        ``(..., 3, 3)``.
    """
    # Fixed-axis (extrinsic) order a, b, c == intrinsic order c, b, a with reversed angles.
    return euler_to_matrix(angles.flip(-1), order.upper()[::-1])


@dataclass
class AsfBone:
    """One ``:bonedata`` entry.

    Attributes:
        name: bone name; ``direction``: ``(3,)`` unit vector (world, base pose);
        length: file units; ``axis``: ``(3,)`` angles (radians) of the bone frame ``C``;
        axis_order: letters, e.g. ``"XYZ"``; dof: tokens in file order (``rx``, ``ty``, ``l``...);
        limits: ``(len(dof), 2)`` (radians for rotations, file units otherwise; ``inf`` allowed);
        line: line of its ``begin`` (for messages).
    """

    name: str
    direction: np.ndarray
    length: float
    axis: np.ndarray
    axis_order: str
    dof: tuple[str, ...] = ()
    limits: np.ndarray | None = None
    line: int = 0


@dataclass
class AsfSkeleton:
    """A parsed ASF file.

    Attributes:
        name: ``:name``; units_to_m: declared metres per file length unit (``0.0254 / length``);
        length_multiplier: the ``:units length`` value; angle: ``"deg"`` or ``"rad"``;
        root_order: root AMC value tokens (``TX``..., ``RZ``); root_axis: order of the root's
        pre-set orientation; root_position: ``(3,)`` file units; root_orientation: ``(3,)``
        radians; bones: name -> :class:`AsfBone`; parents: bone -> parent (``"root"`` at the top);
        order: bones with parents first (hierarchy order); path: the file.
    """

    name: str
    units_to_m: float
    length_multiplier: float
    angle: str
    root_order: tuple[str, ...]
    root_axis: str
    root_position: np.ndarray
    root_orientation: np.ndarray
    bones: dict[str, AsfBone]
    parents: dict[str, str]
    order: tuple[str, ...]
    path: Path = field(default_factory=lambda: Path("<string>"))


# ---------------------------------------------------------------------------- helpers
def _clean(line: str) -> list[str]:
    """Tokens of one line: '#' starts a comment; commas and parentheses are whitespace."""
    line = line.split("#", 1)[0]
    return line.replace(",", " ").replace("(", " ").replace(")", " ").split()


def _num(path: Path, tok: str, lineno: int, what: str) -> float:
    try:
        v = float(tok)
    except ValueError:
        if tok.lower() in ("inf", "+inf", "-inf"):
            return float(tok.lower().replace("+", ""))
        raise InputFileError(path, f"non-numeric value {tok!r}", what, field=f"line {lineno}") from None
    if math.isnan(v):
        raise InputFileError(path, f"value {tok!r}", what, field=f"line {lineno}")
    return v


def _order(path: Path, tok: str, lineno: int, what: str) -> str:
    o = tok.upper()
    if len(o) != 3 or set(o) != set("XYZ"):
        raise InputFileError(path, f"rotation order {tok!r}", f"{what}: three distinct letters from XYZ, e.g. XYZ", field=f"line {lineno}")
    return o


# ---------------------------------------------------------------------------- ASF
def parse_asf_text(text: str, path: str | Path = "<string>") -> AsfSkeleton:
    """Parse ASF text (semantics in the module doc). ``path`` names the file in errors."""
    path = Path(path)
    lines = [(_clean(ln), i + 1) for i, ln in enumerate(text.splitlines())]
    lines = [(t, n) for t, n in lines if t]
    units = {"mass": 1.0, "length": 1.0, "angle": "deg"}
    name = ""
    root_order: tuple[str, ...] = ("TX", "TY", "TZ", "RX", "RY", "RZ")
    root_axis = "XYZ"
    root_pos_raw = [0.0, 0.0, 0.0]
    root_ori_raw = [0.0, 0.0, 0.0]
    bones_raw: list[dict] = []
    hierarchy: list[tuple[list[str], int]] = []
    section = None
    k = 0
    seen: set[str] = set()
    while k < len(lines):
        toks, ln = lines[k]
        head = toks[0]
        if head.startswith(":"):
            section = head.lower()
            seen.add(section)
            if section == ":name":
                name = " ".join(toks[1:])
            elif section == ":units" and len(toks) > 1:
                raise InputFileError(path, f"unexpected {' '.join(toks[1:])!r} after :units", "':units' alone on its line, then 'mass m', 'length l', 'angle deg|rad' lines", field=f"line {ln}")
            k += 1
            continue
        if section == ":units":
            key = head.lower()
            if key not in ("mass", "length", "angle") or len(toks) != 2:
                raise InputFileError(path, f"unknown units entry {' '.join(toks)!r}", "':units' lines 'mass <number>', 'length <number>', 'angle deg|rad'", field=f"line {ln}")
            if key == "angle":
                a = toks[1].lower()
                if a not in ("deg", "rad", "degree", "degrees", "radian", "radians"):
                    raise InputFileError(path, f"unknown angle unit {toks[1]!r}", "'angle deg' or 'angle rad'", field=f"line {ln}")
                units["angle"] = "deg" if a.startswith("deg") else "rad"
            else:
                v = _num(path, toks[1], ln, f"'{key} <number>' in :units")
                if not (v > 0 and math.isfinite(v)):
                    raise InputFileError(path, f"{key} multiplier {toks[1]!r}", f"a positive number after '{key}' in :units", field=f"line {ln}")
                units[key] = v
        elif section == ":root":
            key = head.lower()
            if key == "order":
                root_order = tuple(t.upper() for t in toks[1:])
                bad = [t for t in root_order if t not in ("TX", "TY", "TZ", "RX", "RY", "RZ")]
                if bad or len(set(root_order)) != len(root_order):
                    raise InputFileError(path, f"root order {' '.join(toks[1:])!r}", "distinct tokens from TX TY TZ RX RY RZ", field=f"line {ln}")
            elif key == "axis":
                if len(toks) != 2:
                    raise InputFileError(path, f"root axis line {' '.join(toks)!r}", "'axis XYZ' (the order of the root's pre-set orientation)", field=f"line {ln}")
                root_axis = _order(path, toks[1], ln, "root axis")
            elif key in ("position", "orientation"):
                if len(toks) != 4:
                    raise InputFileError(path, f"root {key} has {len(toks) - 1} values", f"'{key} x y z'", field=f"line {ln}")
                vals = [_num(path, t, ln, f"root {key}: three numbers") for t in toks[1:]]
                if key == "position":
                    root_pos_raw = vals
                else:
                    root_ori_raw = vals
            else:
                raise InputFileError(path, f"unknown root entry {head!r}", "root lines 'order ...', 'axis ...', 'position x y z', 'orientation x y z'", field=f"line {ln}")
        elif section == ":bonedata":
            if head.lower() != "begin":
                raise InputFileError(path, f"found {head!r}", "'begin' opening a bone in :bonedata", field=f"line {ln}")
            bone: dict = {"line": ln}
            k += 1
            while True:
                if k >= len(lines):
                    raise InputFileError(path, f"bone opened at line {ln} is not closed", "'end' closing each bone", field=f"line {ln}")
                toks, bl = lines[k]
                key = toks[0].lower()
                if key == "end":
                    break
                if key == "limits":
                    ndof = len(bone.get("dof", ()))
                    vals: list[float] = []
                    rest = toks[1:]
                    while True:
                        vals += [_num(path, t, bl, "limits: (min max) pairs, one per dof") for t in rest]
                        if len(vals) >= 2 * ndof:
                            break
                        k += 1
                        if k >= len(lines):
                            break
                        rest, bl = lines[k]
                    if len(vals) != 2 * ndof:
                        raise InputFileError(path, f"bone {bone.get('name', '?')}: {len(vals) // 2} limit pairs for {ndof} dofs",
                                             "one '(min max)' pair per dof after 'limits'", field=f"line {bl}")
                    bone["limits"] = np.asarray(vals, dtype=np.float64).reshape(ndof, 2)
                elif key == "name":
                    if len(toks) != 2:
                        raise InputFileError(path, f"bone name line {' '.join(toks)!r}", "'name <bone>' (one word)", field=f"line {bl}")
                    bone["name"] = toks[1]
                elif key == "id":
                    pass
                elif key == "direction":
                    if len(toks) != 4:
                        raise InputFileError(path, f"bone {bone.get('name', '?')}: direction has {len(toks) - 1} values", "'direction x y z'", field=f"line {bl}")
                    bone["direction"] = np.array([_num(path, t, bl, "direction x y z") for t in toks[1:]])
                elif key == "length":
                    if len(toks) != 2:
                        raise InputFileError(path, f"bone {bone.get('name', '?')}: length line {' '.join(toks)!r}", "'length <number>'", field=f"line {bl}")
                    bone["length"] = _num(path, toks[1], bl, "'length <number>'")
                elif key == "axis":
                    if len(toks) != 5:
                        raise InputFileError(path, f"bone {bone.get('name', '?')}: axis line {' '.join(toks)!r}", "'axis ax ay az XYZ' (three angles and their order)", field=f"line {bl}")
                    bone["axis"] = np.array([_num(path, t, bl, "axis ax ay az ORDER") for t in toks[1:4]])
                    bone["axis_order"] = _order(path, toks[4], bl, f"axis order of bone {bone.get('name', '?')}")
                elif key == "dof":
                    dof = tuple(t.lower() for t in toks[1:])
                    bad = [t for t in dof if t not in _CHANNEL_NAME]
                    if bad or len(set(dof)) != len(dof):
                        raise InputFileError(path, f"bone {bone.get('name', '?')}: dof {' '.join(toks[1:])!r}", f"distinct {_DOF_FORM}", field=f"line {bl}")
                    bone["dof"] = dof
                elif key in ("bodymass", "cofmass"):
                    pass
                else:
                    raise InputFileError(path, f"unknown bone entry {toks[0]!r} in bone {bone.get('name', '?')}",
                                         "bone lines id, name, direction, length, axis, dof, limits, bodymass, cofmass, end", field=f"line {bl}")
                k += 1
            for req in ("name", "direction", "length", "axis"):
                if req not in bone:
                    raise InputFileError(path, f"bone {bone.get('name', '?')} has no '{req}'", "every bone to give name, direction, length and axis",
                                         field=f"line {bone['line']}")
            bones_raw.append(bone)
        elif section == ":hierarchy":
            if head.lower() in ("begin", "end"):
                k += 1
                continue
            hierarchy.append((toks, ln))
        elif section in (":version", ":documentation", ":skin", ":name"):
            pass
        elif section is None:
            raise InputFileError(path, f"found {head!r} before any keyword", "an ASF file starting with ':version', ':name', ':units'...", field=f"line {ln}")
        k += 1
    if ":bonedata" not in seen or ":hierarchy" not in seen:
        missing = [s for s in (":bonedata", ":hierarchy") if s not in seen]
        raise InputFileError(path, f"no {' and '.join(missing)} section", "an ASF skeleton file (:units, :root, :bonedata, :hierarchy)", field=missing[0])

    to_rad = math.pi / 180.0 if units["angle"] == "deg" else 1.0
    bones: dict[str, AsfBone] = {}
    for b in bones_raw:
        if b["name"] in bones or b["name"] == "root":
            raise InputFileError(path, f"bone name {b['name']!r} used twice", "unique bone names (and none called root)", field=f"line {b['line']}")
        d = b["direction"]
        n = float(np.linalg.norm(d))
        if b["length"] != 0 and n < 1e-9:
            raise InputFileError(path, f"bone {b['name']}: zero direction", "a non-zero 'direction x y z'", field=f"line {b['line']}")
        dof = b.get("dof", ())
        lim = b.get("limits")
        if lim is not None:
            lim = lim.copy()
            for i, t in enumerate(dof):
                if t in _ROT_DOFS:
                    lim[i] *= to_rad
        bones[b["name"]] = AsfBone(b["name"], d / n if n > 0 else d, float(b["length"]), b["axis"] * to_rad,
                                   b.get("axis_order", "XYZ"), dof, lim, b["line"])
    parents: dict[str, str] = {}
    for toks, ln in hierarchy:
        par = toks[0]
        if par != "root" and par not in bones:
            raise InputFileError(path, f"hierarchy names unknown bone {par!r}", "bone names defined in :bonedata (or root)", field=f"line {ln}")
        for c in toks[1:]:
            if c not in bones:
                raise InputFileError(path, f"hierarchy names unknown bone {c!r}", "bone names defined in :bonedata", field=f"line {ln}")
            if c in parents:
                raise InputFileError(path, f"bone {c!r} has two parents ({parents[c]}, {par})", "each bone listed once as a child", field=f"line {ln}")
            parents[c] = par
    order: list[str] = []
    frontier = ["root"]
    while frontier:
        p = frontier.pop(0)
        kids = [c for toks, _ in hierarchy if toks[0] == p for c in toks[1:]]
        order += kids
        frontier += kids
    orphans = [b for b in bones if b not in order]
    if orphans:
        raise InputFileError(path, f"bones not connected to the root: {orphans}", "every bone reachable from root in :hierarchy", field=":hierarchy")
    return AsfSkeleton(name, INCH_TO_M / units["length"], float(units["length"]), str(units["angle"]), root_order, root_axis,
                       np.asarray(root_pos_raw, dtype=np.float64), np.asarray(root_ori_raw, dtype=np.float64) * to_rad,
                       bones, parents, tuple(order), path)


def read_asf(path: str | Path) -> AsfSkeleton:
    """Read an ``.asf`` (optionally ``.gz``) skeleton file."""
    path = Path(path)
    return parse_asf_text(read_text_file(path, "an Acclaim skeleton file (.asf)"), path)


# ---------------------------------------------------------------------------- AMC
def parse_amc_text(text: str, asf: AsfSkeleton, path: str | Path = "<string>", strict: bool = False) -> dict[str, np.ndarray]:
    """Parse AMC text (fully specified frames) against ``asf``. ``strict`` checks every value as
    it is read (used when a NaN turned up, to name its line).

    Returns:
        bone name (and ``"root"``) -> ``(T, k)`` values in the dof / root ``order`` listing
        (angles converted to radians; lengths in file units).
    """
    path = Path(path)
    ndof = {"root": len(asf.root_order), **{n: len(b.dof) for n, b in asf.bones.items()}}
    animated = [n for n, k in ndof.items() if k > 0]
    regular = None if strict else _parse_regular_amc(text, ndof, animated)
    if regular is not None:
        return _amc_values(path, asf, *regular)
    raw = text.splitlines()
    frames: list[dict[str, list[float]]] = []
    frame_lines: list[int] = []
    declared = None
    cur: dict[str, list[float]] | None = None
    expected_next: int | None = None

    def close(frame: dict[str, list[float]], ln: int) -> None:
        missing = [n for n in animated if n not in frame]
        if missing:
            raise InputFileError(path, f"frame {len(frames)} has no line for bone(s) {', '.join(missing[:5])}",
                                 "fully specified frames: a line 'bone v1 v2 ...' for every bone with dofs (and root) after each frame number",
                                 field=f"line {ln}, bone {missing[0]}")

    for i, line in enumerate(raw):
        # Most lines hold no comment or punctuation: a plain split is 2x faster than _clean.
        toks = _clean(line) if ("#" in line or "," in line or "(" in line or ")" in line) else line.split()
        if not toks:
            continue
        ln = i + 1
        head = toks[0]
        if head.startswith(":"):
            h = head.upper()
            if h in (":DEGREES", ":DEGREE"):
                declared = "deg"
            elif h in (":RADIANS", ":RADIAN"):
                declared = "rad"
            elif h not in (":FULLY-SPECIFIED", ":FULLY_SPECIFIED"):
                raise InputFileError(path, f"unknown AMC keyword {head!r}", ":FULLY-SPECIFIED, :DEGREES or :RADIANS", field=f"line {ln}")
            continue
        if len(toks) == 1 and toks[0].lstrip("-").isdigit():
            if cur is not None:
                close(cur, ln - 1)
                frames.append(cur)
            n = int(toks[0])
            if expected_next is not None and n != expected_next:
                raise InputFileError(path, f"frame number {n} after frame {expected_next - 1}", "consecutive frame numbers", field=f"line {ln}")
            expected_next = n + 1
            cur = {}
            frame_lines.append(ln)
            continue
        if cur is None:
            raise InputFileError(path, f"found {head!r} before the first frame number", "a frame number line (e.g. '1') before bone lines", field=f"line {ln}")
        if head not in ndof:
            raise InputFileError(path, f"unknown bone {head!r}", f"bone names of the ASF skeleton {asf.path.name}", field=f"line {ln}, bone {head}")
        vals = toks[1:]
        if len(vals) != ndof[head]:
            form = " ".join(asf.root_order) if head == "root" else " ".join(asf.bones[head].dof)
            raise InputFileError(path, f"bone {head} has {len(vals)} values in frame {len(frames)}",
                                 f"{ndof[head]} values ({form}) as declared in the ASF", field=f"line {ln}, bone {head}")
        if head in cur:
            raise InputFileError(path, f"bone {head} given twice in frame {len(frames)}", "one line per bone per frame", field=f"line {ln}, bone {head}")
        try:
            nums = [float(v) for v in vals]
        except ValueError:
            nums = [_num(path, v, ln, f"numbers for bone {head}") for v in vals]
        if strict:
            nums = [_num(path, v, ln, f"numbers for bone {head}") for v in vals]
        cur[head] = nums
    if cur is not None:
        close(cur, len(raw))
        frames.append(cur)
    if not frames:
        raise InputFileError(path, "no frames", "frame number lines each followed by one line per bone", field="MOTION")
    values = {n: np.asarray([f[n] for f in frames], dtype=np.float64) for n in animated}
    if not strict and any(np.isnan(v).any() for v in values.values()):
        return parse_amc_text(text, asf, path, strict=True)  # a 'nan' value: find and name its line
    return _amc_values(path, asf, declared, values)


def _amc_values(path: Path, asf: AsfSkeleton, declared: str | None, values: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Check the declared angle unit against the ASF's and convert rotation values to radians."""
    if declared is not None and declared != asf.angle:
        raise InputFileError(path, f"angles declared {declared} here but {asf.angle} in the ASF {asf.path.name}",
                             "the same angle unit in both files", field=":DEGREES/:RADIANS")
    to_rad = math.pi / 180.0 if asf.angle == "deg" else 1.0
    for n, arr in values.items():
        toks = asf.root_order if n == "root" else asf.bones[n].dof
        for c, t in enumerate(toks):
            if t.lower() in _ROT_DOFS:
                arr[:, c] *= to_rad
    return values


def _parse_regular_amc(text: str, ndof: dict[str, int], animated: list[str]) -> tuple[str | None, dict[str, np.ndarray]] | None:
    """Fast path for the common layout (CMU, Vicon exports): header keywords, then frames
    numbered 1, 2, 3... each listing every animated bone once, in the same order every frame,
    with plain numbers. Reads each bone's column of lines at once (5-10x faster than line by
    line). Returns ``(declared angle unit, raw values)``, or ``None`` for anything else; the
    general parser then reads the file and names any problem with its line."""
    lines = [ln.strip() for ln in text.splitlines()]
    lines = [ln for ln in lines if ln and not ln.startswith("#")]
    k = 0
    declared = None
    while k < len(lines) and lines[k].startswith(":"):
        h = lines[k].split()[0].upper()
        if h in (":DEGREES", ":DEGREE"):
            declared = "deg"
        elif h in (":RADIANS", ":RADIAN"):
            declared = "rad"
        elif h not in (":FULLY-SPECIFIED", ":FULLY_SPECIFIED") or len(lines[k].split()) > 1:
            return None
        k += 1
    body = lines[k:]
    step = len(animated) + 1
    if not body or len(body) % step or not body[0].isdigit():
        return None
    T = len(body) // step
    first = int(body[0])
    if body[0::step] != [str(first + t) for t in range(T)]:
        return None
    names = [ln.split(None, 1)[0] for ln in body[1:step]]
    if sorted(names) != sorted(animated):
        return None
    values: dict[str, np.ndarray] = {}
    for i, name in enumerate(names, start=1):
        col = body[i::step]
        head = name + " "
        if any(not ln.startswith(head) for ln in col):
            return None
        joined = " ".join(ln[len(head):] for ln in col)
        if "#" in joined or "," in joined or "(" in joined or ")" in joined:
            return None
        try:
            arr = np.array(joined.split(), dtype=np.float64)
        except ValueError:
            return None
        if arr.size != T * ndof[name] or np.isnan(arr).any():
            return None
        values[name] = arr.reshape(T, ndof[name])
    return declared, values


def asf_amc_to_motion(asf: AsfSkeleton, values: dict[str, np.ndarray], fps: float | None = None,
                      amc_path: str | Path | None = None) -> BvhMotion:
    """Build the joint-tree motion (see module doc) from a skeleton and parsed AMC values."""
    fps_assumed = fps is None
    fps = DEFAULT_AMC_FPS if fps is None else float(fps)
    T = next(iter(values.values())).shape[0] if values else 1
    names = ["root", *asf.order]
    idx = {n: i for i, n in enumerate(names)}
    J = len(names)
    parents = [-1] + [idx[asf.parents[n]] for n in asf.order]
    f64 = torch.float64
    rot = torch.eye(3, dtype=f64).repeat(T, J, 1, 1)
    trans = torch.zeros(T, J, 3, dtype=f64)
    offsets = np.zeros((J, 3))
    # Root.
    rv = torch.from_numpy(values.get("root", np.zeros((T, len(asf.root_order)))))
    O = acclaim_rotation(torch.from_numpy(asf.root_orientation), asf.root_axis)
    rtoks = [t for t in asf.root_order if t.startswith("R")]
    if rtoks:
        cols = [asf.root_order.index(t) for t in rtoks]
        M = acclaim_rotation(rv[:, cols], "".join(t[1] for t in rtoks))
        rot[:, 0] = M @ O
    else:
        rot[:, 0] = O
    trans[:, 0] = torch.from_numpy(asf.root_position)
    for t in ("TX", "TY", "TZ"):
        if t in asf.root_order:
            trans[:, 0, "XYZ".index(t[1])] += rv[:, asf.root_order.index(t)]
    channels: list[tuple[str, ...]] = [tuple(_CHANNEL_NAME[t.lower()] for t in asf.root_order)]
    end_sites: dict[int, np.ndarray] = {}
    has_children = set(asf.parents.values())
    for n in asf.order:
        j = idx[n]
        b = asf.bones[n]
        channels.append(tuple(_CHANNEL_NAME[t] for t in b.dof))
        p = asf.parents[n]
        # Start of this bone: the end of the parent bone (the root's children start at the root).
        if p != "root":
            pb = asf.bones[p]
            offsets[j] = pb.direction * pb.length
            trans[:, j] = torch.from_numpy(offsets[j])
            if "l" in pb.dof:
                dl = torch.from_numpy(values[p][:, pb.dof.index("l")])
                trans[:, j] = trans[:, j] + dl[:, None] * torch.from_numpy(pb.direction)
        C = acclaim_rotation(torch.from_numpy(b.axis), b.axis_order)
        v = values.get(n)
        rdofs = [t for t in b.dof if t in _ROT_DOFS]
        if rdofs and v is not None:
            cols = [b.dof.index(t) for t in rdofs]
            M = acclaim_rotation(torch.from_numpy(v[:, cols]), "".join(_ROT_DOFS[t] for t in rdofs))
            rot[:, j] = C @ M @ C.T
        tdofs = [t for t in b.dof if t in _TRANS_DOFS]
        if tdofs and v is not None:
            t_local = torch.zeros(T, 3, dtype=f64)
            for t in tdofs:
                t_local[:, _TRANS_DOFS[t]] = torch.from_numpy(v[:, b.dof.index(t)])
            trans[:, j] = trans[:, j] + t_local @ C.T
        if n not in has_children:
            end_sites[j] = (b.direction * b.length)[None, :]
    skel = BvhSkeleton(tuple(names), tuple(parents), offsets, tuple(channels), end_sites)
    meta = {"format": "asf/amc", "asf_file": str(asf.path), "units_to_m": asf.units_to_m,
            "units_declared": f"ASF :units length {asf.length_multiplier:g} (1 unit = 1/{asf.length_multiplier:g} inch)",
            "angle": asf.angle, "fps_assumed": fps_assumed}
    return BvhMotion(skel, 1.0 / fps, rot, trans, Path(amc_path) if amc_path is not None else asf.path, meta)


def find_asf_for(amc: str | Path) -> Path:
    """The skeleton file of an AMC clip: ``<stem>.asf``; else ``<subject>.asf`` for CMU-style
    names ``<subject>_<take>.amc``; else the only ``.asf`` in the folder.

    Raises:
        InputFileError: none or several candidates.
    """
    amc = Path(amc)
    stem = amc.name[:-len(".amc.gz")] if amc.name.endswith(".amc.gz") else amc.stem
    folder = amc.parent
    cands = [folder / f"{stem}.asf", folder / f"{stem.split('_')[0]}.asf"]
    for c in cands:
        if c.is_file():
            return c
    found = sorted(folder.glob("*.asf"))
    if len(found) == 1:
        return found[0]
    problem = "no .asf skeleton beside it" if not found else f"{len(found)} .asf files beside it and none named {stem}.asf or {stem.split('_')[0]}.asf"
    raise InputFileError(amc, problem, "the ASF skeleton next to the AMC, named <clip>.asf or <subject>.asf (CMU: 02.asf for 02_01.amc), "
                         "or the only .asf in the folder; or name it: --asf FILE (Python: asf=)")


def read_asf_amc(amc: str | Path, asf: str | Path | AsfSkeleton | None = None, fps: float | None = None) -> BvhMotion:
    """Read an AMC motion with its ASF skeleton into a joint-tree :class:`BvhMotion`.

    Args:
        amc: the ``.amc`` file (optionally ``.gz``).
        asf: the skeleton (path or parsed); default :func:`find_asf_for`.
        fps: frame rate (AMC stores none); default :data:`DEFAULT_AMC_FPS`.

    Returns:
        :class:`BvhMotion` in file units and the file's world; ``meta`` holds the declared units.
    """
    amc = Path(amc)
    skel = asf if isinstance(asf, AsfSkeleton) else read_asf(find_asf_for(amc) if asf is None else asf)
    values = parse_amc_text(read_text_file(amc, "an Acclaim motion file (.amc)"), skel, amc)
    return asf_amc_to_motion(skel, values, fps, amc)

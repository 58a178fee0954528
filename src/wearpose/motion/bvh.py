"""BVH reader: HIERARCHY + MOTION, plain ``.bvh`` or gzipped ``.bvh.gz``.

Semantics (the common reading, also Blender's):

- Each joint's local transform is ``x_parent = R_j @ x_local + t_j``.
- ``R_j`` is the product of the joint's rotation channels **in the order they are listed**
  (``Zrotation Xrotation Yrotation`` -> ``R = Rz @ Rx @ Ry``, intrinsic), angles in degrees.
- ``t_j`` is the joint's ``OFFSET``; position channels, when present, **replace** the matching
  OFFSET component (not add to it). The Bandai corpus needs this: its ``Hips`` OFFSET is a
  stale start position while its position channels are absolute.
- Any number (0-6 or more) and order of channels per joint is accepted; units are whatever the
  file uses (the corpus: centimetres). The BVH world is returned unchanged (the corpus files are
  Y up, facing +Z, left at +X, the same as wearpose's).

Every malformed input raises :class:`wearpose.errors.InputFileError` naming the file, the line
(and value) concerned, the problem and the expected form.
"""

from __future__ import annotations

import gzip
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from wearpose.errors import InputFileError
from wearpose.geometry import euler_to_matrix
from wearpose.geometry.units import DEG_TO_RAD

ROTATION_CHANNELS: dict[str, str] = {"Xrotation": "X", "Yrotation": "Y", "Zrotation": "Z"}
POSITION_CHANNELS: dict[str, int] = {"Xposition": 0, "Yposition": 1, "Zposition": 2}
_CHANNEL_FORM = "channel names from Xposition Yposition Zposition Xrotation Yrotation Zrotation"


@dataclass(frozen=True)
class BvhSkeleton:
    """The HIERARCHY of a BVH file (joints in file order; parents precede children).

    Attributes:
        names: ``(J,)`` joint names.
        parents: ``(J,)`` parent index, ``-1`` for the root.
        offsets: ``(J, 3)`` OFFSET of each joint in its parent's frame, file units.
        channels: per joint, its channel names in file order.
        end_sites: joint index -> ``(k, 3)`` OFFSETs of its End Sites (usually ``k = 1``).
    """

    names: tuple[str, ...]
    parents: tuple[int, ...]
    offsets: np.ndarray
    channels: tuple[tuple[str, ...], ...]
    end_sites: dict[int, np.ndarray] = field(default_factory=dict)

    @property
    def num_joints(self) -> int:
        return len(self.names)

    @property
    def num_channels(self) -> int:
        return sum(len(c) for c in self.channels)

    def index(self, name: str) -> int:
        """Index of joint ``name`` (KeyError if absent)."""
        return self.names.index(name)

    def children(self, j: int) -> list[int]:
        return [i for i, p in enumerate(self.parents) if p == j]


@dataclass
class BvhMotion:
    """A parsed BVH clip.

    Attributes:
        skeleton: the hierarchy.
        frame_time: seconds per frame.
        rotations: ``(T, J, 3, 3)`` float64 local rotations (joint frame -> parent frame).
        translations: ``(T, J, 3)`` float64 local translations (OFFSET with position channels
            substituted), file units.
        path: the file read (for messages and provenance).
    """

    skeleton: BvhSkeleton
    frame_time: float
    rotations: torch.Tensor
    translations: torch.Tensor
    path: Path | None = None
    #: Facts from the reader beyond BVH itself (ASF/AMC: ``format``, declared ``units_to_m``,
    #: ``angle``, ``fps_assumed``); empty for BVH files.
    meta: dict = field(default_factory=dict)

    @property
    def num_frames(self) -> int:
        return int(self.rotations.shape[0])

    @property
    def fps(self) -> float:
        """Frames per second, ``1 / frame_time`` snapped to the nearest integer when within 0.01%
        of it (files round the frame time: ``0.0166667`` means 60 Hz, not 59.99988)."""
        fps = 1.0 / self.frame_time
        r = round(fps)
        return float(r) if r > 0 and abs(fps - r) <= 1e-4 * fps else fps


# ---------------------------------------------------------------------------- reading text
def read_text_file(path: Path, what: str = "a BVH file (.bvh or .bvh.gz)") -> str:
    """Text of a plain or gzipped (``.gz``) file; :class:`InputFileError` naming ``what`` was expected."""
    if not path.is_file():
        raise InputFileError(path, "file not found", what)
    try:
        if path.suffix == ".gz":
            with gzip.open(path, "rt", encoding="utf-8", errors="replace") as f:
                return f.read()
        return path.read_text(encoding="utf-8", errors="replace")
    except (OSError, EOFError, gzip.BadGzipFile) as exc:
        raise InputFileError(path, f"cannot read the file ({exc})", f"{what}, optionally gzip-compressed") from exc


class _Tokens:
    """Whitespace tokens of the HIERARCHY with their 1-based line numbers."""

    def __init__(self, lines: list[str], first_line: int, path: Path):
        self.items: list[tuple[str, int]] = []
        for k, line in enumerate(lines):
            for tok in line.split():
                self.items.append((tok, first_line + k))
        self.i = 0
        self.path = path
        self.last_line = first_line + max(len(lines) - 1, 0)

    def peek(self) -> str | None:
        return self.items[self.i][0] if self.i < len(self.items) else None

    def line(self) -> int:
        return self.items[self.i][1] if self.i < len(self.items) else self.last_line

    def next(self, expected: str) -> tuple[str, int]:
        if self.i >= len(self.items):
            raise InputFileError(self.path, "HIERARCHY ends early", expected, field=f"line {self.last_line}")
        tok = self.items[self.i]
        self.i += 1
        return tok

    def name_on_line(self, line: int, expected: str) -> str:
        """A joint name: the rest of ``line`` (names may hold spaces, e.g. ``Bip01 L Thigh``),
        without a trailing ``{``."""
        words = []
        while self.i < len(self.items) and self.items[self.i][1] == line and self.items[self.i][0] != "{":
            words.append(self.items[self.i][0])
            self.i += 1
        if not words:
            raise InputFileError(self.path, "joint name missing", expected, field=f"line {line}")
        return " ".join(words)

    def expect(self, word: str, expected: str | None = None) -> int:
        tok, line = self.next(expected or f"'{word}'")
        if tok != word:
            raise InputFileError(self.path, f"found {tok!r}", expected or f"'{word}'", field=f"line {line}")
        return line

    def number(self, what: str) -> float:
        tok, line = self.next(what)
        try:
            v = float(tok)
        except ValueError:
            raise InputFileError(self.path, f"non-numeric value {tok!r}", what, field=f"line {line}") from None
        if not np.isfinite(v):
            raise InputFileError(self.path, f"non-finite value {tok!r}", what, field=f"line {line}")
        return v


def _parse_hierarchy(tokens: _Tokens) -> BvhSkeleton:
    names: list[str] = []
    parents: list[int] = []
    offsets: list[list[float]] = []
    channels: list[tuple[str, ...]] = []
    end_sites: dict[int, list[list[float]]] = {}
    path = tokens.path

    def offset(owner: str) -> list[float]:
        tokens.expect("OFFSET", f"'OFFSET x y z' for {owner}")
        return [tokens.number(f"three numbers after OFFSET of {owner}") for _ in range(3)]

    def joint(name: str, parent: int) -> None:
        idx = len(names)
        names.append(name)
        parents.append(parent)
        tokens.expect("{", f"'{{' opening joint {name}")
        offsets.append(offset(f"joint {name}"))
        tok, line = tokens.next(f"'CHANNELS n names...' for joint {name}")
        if tok != "CHANNELS":
            raise InputFileError(path, f"found {tok!r}", f"'CHANNELS n names...' after the OFFSET of joint {name}", field=f"line {line}")
        ntok, nline = tokens.next("a channel count")
        n = _count(path, ntok, nline, f"channel count {ntok!r} of joint {name}", "a non-negative integer after CHANNELS")
        chans = []
        for _ in range(n):
            c, cline = tokens.next(f"{n} channel names for joint {name}")
            if c not in ROTATION_CHANNELS and c not in POSITION_CHANNELS:
                raise InputFileError(path, f"unknown channel name {c!r} for joint {name}", _CHANNEL_FORM, field=f"line {cline}")
            chans.append(c)
        channels.append(tuple(chans))
        while True:
            tok, line = tokens.next(f"'JOINT', 'End Site' or '}}' inside joint {name}")
            if tok == "}":
                return
            if tok == "JOINT":
                joint(tokens.name_on_line(line, "a joint name after JOINT"), idx)
            elif tok == "End":
                tokens.expect("Site", "'End Site'")
                tokens.expect("{", "'{' opening an End Site")
                end_sites.setdefault(idx, []).append(offset(f"the End Site of {name}"))
                tokens.expect("}", "'}' closing an End Site")
            else:
                raise InputFileError(path, f"found {tok!r}", f"'JOINT', 'End Site' or '}}' inside joint {name}", field=f"line {line}")

    tokens.expect("HIERARCHY", "the file to start with 'HIERARCHY'")
    tokens.expect("ROOT", "'ROOT <name>' after HIERARCHY")
    root = tokens.name_on_line(tokens.items[tokens.i - 1][1], "a root joint name")
    joint(root, -1)
    if tokens.peek() is not None:
        raise InputFileError(path, f"unexpected {tokens.peek()!r} after the root joint's closing brace", "'MOTION'", field=f"line {tokens.line()}")
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise InputFileError(path, f"duplicate joint names {dup}", "unique joint names", field="HIERARCHY")
    return BvhSkeleton(tuple(names), tuple(parents), np.asarray(offsets, dtype=np.float64), tuple(channels),
                       {k: np.asarray(v, dtype=np.float64) for k, v in end_sites.items()})


def _count(path: Path, tok: str, lineno: int, problem: str, expected: str) -> int:
    """``tok`` as a non-negative integer (a channel or frame count), else InputFileError at ``lineno``."""
    try:
        n = int(tok)
    except ValueError:
        n = -1
    if n < 0:
        raise InputFileError(path, problem, expected, field=f"line {lineno}")
    return n


def _header_value(path: Path, line: str, lineno: int, key: str, expected: str) -> str:
    # Accept "Frames: 10" and "Frames:10"; "Frame Time: 0.0333".
    s = line.strip()
    if not s.startswith(key):
        raise InputFileError(path, f"found {s[:40]!r}", expected, field=f"line {lineno}")
    return s[len(key):].strip()


def parse_bvh_text(text: str, path: str | Path = "<string>") -> BvhMotion:
    """Parse BVH text (see module doc for the semantics). ``path`` is used in error messages."""
    path = Path(path)
    lines = text.splitlines()
    motion_at = next((i for i, ln in enumerate(lines) if ln.strip() == "MOTION"), None)
    if motion_at is None:
        raise InputFileError(path, "no MOTION section", "a 'MOTION' line after the HIERARCHY, then 'Frames: n' and 'Frame Time: dt'", field="MOTION")
    skel = _parse_hierarchy(_Tokens(lines[:motion_at], 1, path))

    # MOTION header: the next two non-empty lines.
    k = motion_at + 1
    header: list[tuple[str, int]] = []
    while k < len(lines) and len(header) < 2:
        if lines[k].strip():
            header.append((lines[k], k + 1))
        k += 1
    if len(header) < 2:
        raise InputFileError(path, "MOTION header ends early", "'Frames: n' and 'Frame Time: dt' after MOTION", field=f"line {len(lines)}")
    (fl, fn), (tl, tn) = header
    fval = _header_value(path, fl, fn, "Frames:", "'Frames: n' (n a non-negative integer)")
    n_frames = _count(path, fval, fn, f"frame count {fval!r}", "'Frames: n' (n a non-negative integer)")
    tval = _header_value(path, tl, tn, "Frame Time:", "'Frame Time: dt' (seconds per frame, > 0)")
    try:
        frame_time = float(tval)
        if not (frame_time > 0 and np.isfinite(frame_time)):
            raise ValueError
    except ValueError:
        raise InputFileError(path, f"frame time {tval!r}", "'Frame Time: dt' (seconds per frame, > 0)", field=f"line {tn}") from None

    C = skel.num_channels
    rows: list[list[str]] = []
    row_lines: list[int] = []
    for i in range(k, len(lines)):
        toks = lines[i].split()
        if not toks:
            continue  # blank lines (e.g. a trailing newline) carry no frame
        if len(rows) == n_frames:
            raise InputFileError(path, f"more motion lines than the {n_frames} frames declared", f"exactly {n_frames} lines of {C} numbers", field=f"line {i + 1}")
        if len(toks) != C:
            raise InputFileError(path, f"frame {len(rows)} has {len(toks)} values", f"{C} numbers per frame line (the channels declared in HIERARCHY)", field=f"line {i + 1}")
        rows.append(toks)
        row_lines.append(i + 1)
    if len(rows) < n_frames:
        raise InputFileError(path, f"truncated motion: {len(rows)} frame lines for the {n_frames} declared", f"{n_frames} lines of {C} numbers", field=f"line {len(lines)}")
    try:
        values = np.array(rows, dtype=np.float64).reshape(n_frames, C)
    except ValueError:
        values = None
    if values is None or not np.all(np.isfinite(values)):
        # Slow path only on failure: find the first offending value for the message.
        chan_names = [f"{skel.names[j]} {c}" for j in range(skel.num_joints) for c in skel.channels[j]]
        for r, toks in enumerate(rows):
            for c, tok in enumerate(toks):
                try:
                    ok = np.isfinite(float(tok))
                except ValueError:
                    ok = False
                if not ok:
                    raise InputFileError(path, f"non-numeric value {tok!r} in frame {r}", "finite decimal numbers",
                                         field=f"line {row_lines[r]}, value {c + 1} ({chan_names[c]})")
        raise InputFileError(path, "unparseable motion values", "finite decimal numbers", field="MOTION")  # pragma: no cover
    rot, trans = channels_to_local(skel, values)
    return BvhMotion(skel, frame_time, rot, trans, path)


def channels_to_local(skel: BvhSkeleton, values: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
    """Channel values ``(T, C)`` (file order; degrees, file units) -> local rotations
    ``(T, J, 3, 3)`` and translations ``(T, J, 3)`` (float64)."""
    T = values.shape[0]
    J = skel.num_joints
    vals = torch.from_numpy(np.ascontiguousarray(values, dtype=np.float64))
    rot = torch.eye(3, dtype=torch.float64).repeat(T, J, 1, 1)
    trans = torch.from_numpy(skel.offsets).to(torch.float64).unsqueeze(0).repeat(T, 1, 1)
    col = 0
    for j, chans in enumerate(skel.channels):
        order = ""
        rcols: list[int] = []
        for c in chans:
            if c in ROTATION_CHANNELS:
                order += ROTATION_CHANNELS[c]
                rcols.append(col)
            else:
                trans[:, j, POSITION_CHANNELS[c]] = vals[:, col]
            col += 1
        if order:
            rot[:, j] = euler_to_matrix(vals[:, rcols] * DEG_TO_RAD, order)
    return rot, trans


def read_bvh(path: str | Path) -> BvhMotion:
    """Read a ``.bvh`` or ``.bvh.gz`` file.

    Returns:
        :class:`BvhMotion` (local rotations ``(T, J, 3, 3)``, translations ``(T, J, 3)`` in the
        file's units and world).

    Raises:
        InputFileError: missing/unreadable file, malformed HIERARCHY, unknown channel name,
            wrong value count on a motion line, non-numeric value, truncated motion.
    """
    path = Path(path)
    return parse_bvh_text(read_text_file(path), path)


def bvh_forward_kinematics(motion: BvhMotion) -> tuple[torch.Tensor, torch.Tensor]:
    """World joint rotations ``(T, J, 3, 3)`` (joint frame -> BVH world) and positions
    ``(T, J, 3)`` (file units, BVH world)."""
    return forward_kinematics_local(motion.skeleton.parents, motion.rotations, motion.translations)


def forward_kinematics_local(parents: tuple[int, ...] | list[int], rot: torch.Tensor, trans: torch.Tensor
                             ) -> tuple[torch.Tensor, torch.Tensor]:
    """FK for a tree given per-frame local rotations ``(T, J, 3, 3)`` and translations ``(T, J, 3)``."""
    g_rot: list[torch.Tensor] = []
    g_pos: list[torch.Tensor] = []
    for j, p in enumerate(parents):
        if p < 0:
            g_rot.append(rot[:, j])
            g_pos.append(trans[:, j])
        else:
            g_rot.append(g_rot[p] @ rot[:, j])
            g_pos.append(g_pos[p] + (g_rot[p] @ trans[:, j].unsqueeze(-1)).squeeze(-1))
    return torch.stack(g_rot, 1), torch.stack(g_pos, 1)


def end_site_positions(motion: BvhMotion, world_rot: torch.Tensor, world_pos: torch.Tensor) -> dict[int, torch.Tensor]:
    """World positions ``(T, k, 3)`` of each joint's End Sites (file units), keyed by joint index."""
    out = {}
    for j, offs in motion.skeleton.end_sites.items():
        o = torch.from_numpy(offs).to(world_rot)  # (k, 3)
        out[j] = world_pos[:, j, None, :] + torch.einsum("tab,kb->tka", world_rot[:, j], o)
    return out

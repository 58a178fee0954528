"""The prepared corpus: every clip converted once to a :class:`MotionSequence` file plus an index.

Layout of a cache directory::

    <cache>/index.json                          clip table, failures, settings
    <cache>/clips/<source>/<subject>/<clip>.npz MotionSequence files (MotionSequence.save)

Clip ids are ``"<source>/<subject>/<clip>"`` (clip names repeat across subjects, e.g. ``01``).
"""

from __future__ import annotations

import copy
import csv
import hashlib
import re
import json
import multiprocessing
import os
import time
from collections.abc import Collection, Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any

import torch

from wearpose.fileio import atomic_write_text
from wearpose.errors import ConfigError, InputFileError, WearposeError
from wearpose.motion.amass import read_amass
from wearpose.motion.asf import find_asf_for
from wearpose.motion.bvh import read_bvh
from wearpose.motion.importer import UP_AXES, import_motion
from wearpose.motion.paths import cache_dir as default_cache_dir
from wearpose.motion.paths import data_dir as default_data_dir
from wearpose.motion.resample import resample
from wearpose.motion.retarget import lowest_foot_height, retarget_bvh
from wearpose.motion.sequence import MotionSequence
from wearpose.motion.template import default_rest_joints

INDEX_NAME = "index.json"
INDEX_VERSION = 1
#: Bump when the conversion changes so that existing caches are rebuilt. motion-4: root travel
#: scaled by the hip-to-ankle limb ratio, height by the pelvis-to-ankle ratio as before.
CONVERTER_VERSION = "motion-4"
#: Clips whose lowest ankle/foot joint is further than this from the floor (y = 0) are counted
#: as ``floor_suspect`` in :meth:`CorpusStore.summary` (source data placed off the floor).
FLOOR_TOLERANCE_M = 0.15
SPLITS = ("train", "val", "test")
_SUFFIXES = (".bvh", ".bvh.gz", ".amc", ".amc.gz", ".npz")


def _hash_split(subject: str) -> str:
    """Deterministic split for folders without a manifest: 80/10/10 by a hash of the subject."""
    h = int(hashlib.sha1(subject.encode("utf-8")).hexdigest()[:8], 16) / 2**32
    return "train" if h < 0.8 else ("val" if h < 0.9 else "test")


def _clip_name(p: Path) -> str:
    n = p.name
    for s in (".bvh.gz", ".bvh", ".amc.gz", ".amc", ".npz"):
        if n.endswith(s):
            return n[: -len(s)]
    return p.stem


def _read_manifest(data: Path) -> list[dict[str, Any]]:
    path = data / "manifest.csv"
    need = ("path", "source", "subject", "clip", "split")
    with open(path, newline="", encoding="utf-8") as f:
        reader = csv.DictReader(f)
        missing = [c for c in need if c not in (reader.fieldnames or [])]
        if missing:
            raise InputFileError(path, f"missing columns {missing}", f"a CSV header with at least {', '.join(need)}", field="header")
        rows = list(reader)
    out = []
    for i, r in enumerate(rows, start=2):
        if r["split"] not in SPLITS:
            raise InputFileError(path, f"split {r['split']!r}", f"one of {SPLITS}", field=f"line {i}, split")
        out.append({
            "file": _manifest_file(data, r["path"]), "source": r["source"], "subject": r["subject"], "clip": r["clip"],
            "split": r["split"], "licence": r.get("licence", "unknown") or "unknown", "description": r.get("description", ""),
            "skip_first": r.get("frame0_is_tpose", "0").strip() == "1", "manifest_fps": _manifest_fps(path, i, r),
        })
    return out


def _manifest_file(data: Path, rel: str) -> Path:
    """A manifest ``path`` as a file: paths are relative to shared/ and start with the corpus
    folder's original name (``data/cmu_daz/...`` also in ``data-v2``), so the first part is
    dropped inside ``data``; a path already relative to ``data`` is used as it is. Never the
    sibling folder's file of the same name (v2's rows must not read v1's files)."""
    parts = Path(rel).parts
    cands = [data / rel]
    if len(parts) > 1 and parts[0] in ("data", data.name):
        cands.append(data.joinpath(*parts[1:]))
    return next((c for c in cands if c.exists()), cands[-1])


def _manifest_fps(path: Path, line: int, row: dict[str, Any]) -> float | None:
    """The row's ``fps`` (AMC files store none), or None when the column is absent or empty."""
    v = (row.get("fps") or "").strip()
    if not v:
        return None
    try:
        fps = float(v)
    except ValueError:
        fps = float("nan")
    if not fps > 0:
        raise InputFileError(path, f"fps {v!r}", "a positive frame rate in Hz", field=f"line {line}, fps")
    return fps


def _clip_id(row: dict[str, Any]) -> str:
    return f"{row['source']}/{row['subject']}/{row['clip']}"


def _first_per_split(rows: list[dict[str, Any]], n: int, named: Collection[str]) -> list[dict[str, Any]]:
    """The rows of the first ``n`` clip ids (sorted) of each (split, source) and of every id in ``named``."""
    if n < 0:
        raise ConfigError(f"per_split = {n}: expected a clip count >= 0")
    known = {_clip_id(r) for r in rows}
    missing = sorted(set(named) - known)
    if missing:
        raise ConfigError(f"clips {missing} are not in the corpus; expected clip ids such as {min(known, default='?')}")
    keep = set(named)
    for group in {(r["split"], r["source"]) for r in rows}:
        keep.update(sorted(_clip_id(r) for r in rows if (r["split"], r["source"]) == group)[:n])
    return [r for r in rows if _clip_id(r) in keep]


#: ``split=`` values of :func:`prepare_corpus` for users' folders.
USER_SPLITS = ("train", "val", "test", "hash")
SOURCE_NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$")


def _scan_folders(folders: Sequence[Path], split: str = "hash", source: str | None = None) -> list[dict[str, Any]]:
    """Rows for users' folders: subject = parent folder, source = ``source`` or the first folder
    level below the root (else the root's name), split = ``split`` or a hash of the subject."""
    out = []
    for root in folders:
        files = sorted(p for p in root.rglob("*") if p.is_file() and p.name.endswith(_SUFFIXES))
        for p in files:
            subject = p.parent.name if p.parent != root else root.name
            rel = p.relative_to(root)
            src = source or (rel.parts[0] if len(rel.parts) > 2 else root.name)
            out.append({"file": p, "source": src, "subject": subject, "clip": _clip_name(p),
                        "split": _hash_split(subject) if split == "hash" else split, "licence": "unknown", "description": "",
                        "skip_first": False, "user_files": True})
    _refuse_shared_ids(out)
    return out


def _refuse_shared_ids(rows: list[dict[str, Any]]) -> None:
    """Refuse two files that name one clip id (``02_01.bvh.gz`` beside ``02_01.amc.gz``: the id is
    source/subject/file name without its suffix): the store holds one clip per id, so one file
    would have become the clip and the other a failure with no word on why."""
    seen: dict[str, Path] = {}
    for r in rows:
        cid = _clip_id(r)
        if cid in seen:
            raise ConfigError(f"{seen[cid]} and {r['file']} both become clip {cid} (the clip id is the folder and the "
                              "file name without its suffix); keep one of them, or move one into a folder of its own "
                              "and prepare that folder into another store (--cache)")
        seen[cid] = Path(r["file"])


def _check_user_options(split: str | None, source: str | None, manifest: Path | None, asf: Any = None,
                        up: str | None = None) -> None:
    if manifest is not None and (split is not None or source is not None or asf is not None or up is not None):
        raise ConfigError(f"split/source/asf/up apply to your own folders; {manifest} gives every clip's split and source "
                          "(leave out --split, --source, --asf and --up, or point at folders without a manifest.csv)")
    if asf is not None and not Path(asf).is_file():
        raise ConfigError(f"ASF file {asf} does not exist")

    if up is not None and up.lower() not in UP_AXES:
        raise ConfigError(f"up axis {up!r}; expected one of {', '.join(UP_AXES)}")
    if split is not None and split not in USER_SPLITS:
        raise ConfigError(f"split {split!r}; expected one of {', '.join(USER_SPLITS)} (hash: 80/10/10 by a hash of the "
                          "subject folder)")
    if source is not None and not SOURCE_NAME_RE.match(source):
        raise ConfigError(f"source {source!r}; expected 1-64 characters of [A-Za-z0-9_.-] starting with a letter or digit "
                          "(it becomes a folder and the first part of clip ids)")


def _corpus_provenance(data: Path | None, folders: Sequence[Path], split: str | None, source: str | None) -> dict[str, Any]:
    """Which corpus a store was prepared from: a manifest corpus's folder, name and the SHA-1 of
    its manifest (its version: a changed manifest is another corpus); users' folders and the
    split/source given for them."""
    if data is not None and (data / "manifest.csv").is_file():
        sha = hashlib.sha1((data / "manifest.csv").read_bytes()).hexdigest()
        return {"kind": "manifest", "path": str(data.resolve()), "name": data.name, "manifest_sha1": sha}
    return {"kind": "folders", "paths": [str(Path(f).resolve()) for f in folders], "split": split or "hash",
            "source": source}


def _stamp(path: Path, fps: float | None, rest_key: str) -> str:
    st = path.stat()
    return f"{CONVERTER_VERSION}|{st.st_size}|{st.st_mtime_ns}|{fps}|{rest_key}"


def _asf_stamp(amc: Path) -> str:
    """Size and mtime of the ASF an AMC clip reads (``"asf:?"`` when it cannot be found: the
    conversion then fails and says why)."""
    try:
        st = find_asf_for(amc).stat()
    except (WearposeError, OSError):
        return "asf:?"
    return f"asf:{st.st_size}|{st.st_mtime_ns}"


def _convert_one(job: dict[str, Any]) -> dict[str, Any]:
    """Worker: one source file -> one MotionSequence file. Never raises (errors are returned)."""
    torch.set_num_threads(1)  # one process per core; intra-op threads would only contend
    src = Path(job["file"])
    try:
        rest = torch.tensor(job["rest_joints"], dtype=torch.float64)
        meta = {"source_file": str(src), "subject": job["subject"], "clip": job["clip"], "split": job["split"],
                "licence": job["licence"], "source": job["source"], "description": job["description"],
                "rest_joints_source": job["rest_source"]}
        if src.name.endswith(".npz"):
            seq = read_amass(src, rest)
            seq.meta.update(meta)
        elif job.get("user_files"):
            # Folders without a manifest: any skeleton, units and up axis (wearpose.motion.importer).
            seq = import_motion(src, rest, joint_map=job.get("joint_map"), meta=meta, asf=job.get("asf"),
                                up=job.get("up")).sequence
        elif src.name.lower().endswith((".amc", ".amc.gz")):
            seq = _import_corpus_amc(src, rest, job.get("manifest_fps"), meta)
        else:
            seq = retarget_bvh(read_bvh(src), rest, meta=meta).sequence
        if job["skip_first"] and seq.num_frames > 1:
            seq = seq.slice(1)  # the converter's T-pose, not captured motion
            seq.meta["skipped_frame0"] = True
        if job["fps"] is not None:
            seq = resample(seq, job["fps"])
        # Floor check on the frames kept (CMU's T-pose frame 0 sits elsewhere in some clips).
        seq.meta["lowest_foot_y"] = lowest_foot_height(seq.pose, seq.trans, rest)
        seq.save(job["out"])
        return {"ok": True, "id": job["id"], "frames": seq.num_frames, "fps": seq.fps, "seconds": seq.duration,
                "skeleton": seq.meta.get("skeleton"), "lowest_foot_y": round(seq.meta["lowest_foot_y"], 4)}
    except Exception as exc:  # noqa: BLE001 - one bad file must not stop the corpus
        kind = "" if isinstance(exc, WearposeError) else f"{type(exc).__name__}: "
        return {"ok": False, "id": job["id"], "error": f"{kind}{exc}"}


def _import_corpus_amc(src: Path, rest: torch.Tensor, fps: float | None, meta: dict[str, Any]) -> MotionSequence:
    """A manifest row's AMC (its ASF beside it, CMU naming) through the ASF/AMC reader and the
    importer's built-in ``cmu_asf`` map, at the manifest's frame rate (AMC stores none).

    The corpus declares Y up (its README), so the up axis is not guessed; units come from the
    ASF's ``:units``. Any other skeleton is refused: corpus rows must retarget the same way every
    time, not through an automatic match.
    """
    imp = import_motion(src, rest, up="y", fps=fps, meta=meta)
    if not imp.report.map_source.startswith("built-in"):
        raise InputFileError(src, f"its ASF skeleton ({imp.report.map_source} match) is not a built-in one",
                             "a CMU-layout ASF (root, lowerback, lfemur, lhumerus...) beside each corpus AMC")
    return imp.sequence


def _write_json(path: Path, obj: Any) -> None:
    atomic_write_text(path, json.dumps(obj, indent=1, sort_keys=True))


def write_index(cache: Path, clips: dict[str, Any], failures: dict[str, str], *, corpus: dict[str, Any],
                converter: str, fps: float | None, rest_joints: list[list[float]], rest_source: str) -> Path:
    """Write ``<cache>/index.json`` (atomically), the one index format :class:`CorpusStore` reads.

    Args:
        clips: clip id -> entry (``id``, ``clip``, ``subject``, ``source``, ``split``, ``licence``,
            ``description``, ``file`` relative to ``cache``, ``frames``, ``fps``, ``seconds``; an
            optional ``class``, the clip's motion class, :func:`motion_class`).
        failures: clip id -> why it is not in the store.
        corpus: where the clips came from (:meth:`CorpusStore.provenance`'s ``corpus``).
        converter: the version of the code that made the clip files (a changed one rebuilds them).
        fps: the rate every clip was resampled to, or None (each clip's own).
        rest_joints: ``(24, 3)`` rest joints the clips were made for, metres; ``rest_source`` where
            they came from.
    """
    index = {"format": "wearpose.motion.index", "version": INDEX_VERSION, "converter": converter,
             "fps": fps, "rest_joints_source": rest_source, "rest_joints": rest_joints, "corpus": corpus,
             "clips": dict(sorted(clips.items())), "failures": dict(sorted(failures.items()))}
    path = Path(cache) / INDEX_NAME
    _write_json(path, index)
    return path


def motion_class(entry: dict[str, Any]) -> str:
    """The motion class of a store entry: its ``class`` when the store gives one (procedural
    clips: the family), else the corpus description without its ``(style: ...)`` suffix
    (``"wave-left-hand (style: angry)"`` -> ``"wave-left-hand"``), else the clip name."""
    if entry.get("class"):
        return str(entry["class"])
    d = (entry.get("description") or entry.get("clip") or "?").split(" (")[0].strip()
    return d or "?"


def prepare_corpus(data_dir: str | Path | Sequence[str | Path] | None = None, cache_dir: str | Path | None = None,
                   fps: float | None = None, progress: bool = True, workers: int | None = None,
                   rest_joints: torch.Tensor | None = None, limit: int | None = None,
                   joint_map: str | Path | None = None, per_split: int | None = None,
                   clips: Collection[str] = (), split: str | None = None, source: str | None = None,
                   asf: str | Path | None = None, up: str | None = None) -> dict[str, Any]:
    """Convert every corpus clip to a MotionSequence file in ``cache_dir`` and write the index.

    Args:
        data_dir: corpus folder with ``manifest.csv`` (default :func:`wearpose.motion.paths.data_dir`);
            manifest rows may be BVH, AMASS ``.npz`` or ``.amc``/``.amc.gz`` (CMU-layout ASF beside
            it, read at the row's ``fps``: :func:`_import_corpus_amc`);
            or folder(s) without a manifest, in which case every ``.bvh``/``.bvh.gz``/``.amc``
            (with its ``.asf``)/``.npz`` below them is converted, subject = parent folder name,
            split = hash of the subject; their BVH/AMC go through
            :func:`wearpose.motion.import_motion` (any skeleton; units, up axis and rest pose
            detected; the report is in each clip's ``meta["import"]``).
        cache_dir: output (default :func:`wearpose.motion.paths.cache_dir`).
        fps: resample every clip to this rate; ``None`` keeps each clip's own rate.
        progress: show a ``rich`` progress bar.
        workers: processes (default: ``min(2, os.cpu_count())``); ``1`` runs in this process.
        rest_joints: ``(24, 3)`` SMPL rest joints, metres (default: the body model at betas = 0,
            else the SMPL-like template).
        limit: convert only the first ``limit`` clips (for quick checks).
        per_split: convert only the first ``per_split`` clip ids (sorted) of each split of each
            source (and ``clips``): a small store with every split and source of the full one.
        clips: convert only these clip ids (and the ``per_split`` ones); an id that is not in
            the corpus is an error.
        joint_map: YAML joint map for the BVH/AMC of manifest-less folders (see
            :func:`wearpose.motion.mapping.load_joint_map`).
        split: manifest-less folders only: ``"train"``, ``"val"`` or ``"test"`` puts every clip
            in that split (an external test set), ``"hash"`` (default) splits 80/10/10 by a hash
            of the subject folder.
        source: manifest-less folders only: the source name of every clip (default: the first
            folder level below each given folder, else its name).
        asf, up: manifest-less folders only: the ASF skeleton of every AMC file (folders holding
            several actors' ASF files) and the up axis of every file (default: detected), as
            :func:`wearpose.motion.import_motion` takes them.

    Returns:
        ``{"converted", "skipped", "failed", "seconds", "failures": {clip_id: error}, "index": path,
        "store": {"path", "converter", "corpus"}}`` (also in the index: which corpus, and which
        version of it, the store holds; :meth:`CorpusStore.provenance`).
        Conversion is idempotent: entries whose source file, settings and output are unchanged are
        skipped. A failing file is recorded (in the index too) and the rest carries on.
    """
    t0 = time.perf_counter()
    if data_dir is not None and not isinstance(data_dir, (str, Path)):
        given = [Path(d) for d in data_dir]
        with_manifest = [d for d in given if (d / "manifest.csv").is_file()]
        if len(given) == 1:
            # `wearpose data prepare ../shared/data-v2` names one folder: a corpus folder stays a
            # corpus (its manifest's splits, sources and licences), not "your own folders".
            data_dir = given[0]
        elif with_manifest:
            raise ConfigError(f"{with_manifest[0]} is a corpus folder (it has manifest.csv): prepare it on its own "
                              f"(wearpose data prepare {with_manifest[0]}), not together with other folders")
    if data_dir is None or isinstance(data_dir, (str, Path)):
        data: Path | None = default_data_dir(data_dir)
        folders = [data]
        manifest = data / "manifest.csv" if (data / "manifest.csv").is_file() else None
        _check_user_options(split, source, manifest, asf, up)
        jobs_src = _read_manifest(data) if manifest is not None else _scan_folders([data], split or "hash", source)
    else:
        data = None
        folders = [Path(d) for d in data_dir]
        for d in folders:
            if not d.is_dir():
                raise ConfigError(f"data folder {d} does not exist")
        _check_user_options(split, source, None, asf, up)
        jobs_src = _scan_folders(folders, split or "hash", source)
    provenance = _corpus_provenance(data, folders, split, source)
    if joint_map is not None and not Path(joint_map).is_file():
        raise ConfigError(f"joint map {joint_map} does not exist")
    if per_split is not None or clips:
        jobs_src = _first_per_split(jobs_src, per_split or 0, clips)
    if limit is not None:
        jobs_src = jobs_src[:limit]
    cache = default_cache_dir(cache_dir)
    cache.mkdir(parents=True, exist_ok=True)
    if rest_joints is None:
        rest_joints, rest_source = default_rest_joints()
    else:
        rest_source = "argument"
    rest_list = rest_joints.to(torch.float64).tolist()
    rest_key = hashlib.sha1(json.dumps([round(x, 7) for r in rest_list for x in r]).encode()).hexdigest()[:12]

    index_path = cache / INDEX_NAME
    old: dict[str, Any] = {}
    if index_path.is_file():
        try:
            old = json.loads(index_path.read_text(encoding="utf-8")).get("clips", {})
        except (ValueError, OSError):
            old = {}
    clips: dict[str, Any] = {}
    failures: dict[str, str] = {}
    todo: list[dict[str, Any]] = []
    seen: set[str] = set()
    for r in jobs_src:
        cid = _clip_id(r)
        if cid in seen:
            failures[cid] = f"duplicate clip id (second file {r['file']})"
            continue
        seen.add(cid)
        rel_out = Path("clips") / r["source"] / r["subject"] / f"{r['clip']}.npz"
        entry = {"id": cid, "clip": r["clip"], "subject": r["subject"], "source": r["source"], "split": r["split"],
                 "licence": r["licence"], "description": r["description"], "file": rel_out.as_posix(),
                 "source_file": str(r["file"])}
        if not Path(r["file"]).is_file():
            failures[cid] = str(InputFileError(r["file"], "file not found", "the clip listed in manifest.csv"))
            continue
        stamp = _stamp(Path(r["file"]), fps, rest_key)
        if str(r["file"]).lower().endswith((".amc", ".amc.gz")):
            stamp += f"|{_asf_stamp(Path(r['file']))}|fps:{r.get('manifest_fps')}"  # the skeleton is an input too
        if joint_map is not None and r.get("user_files"):
            stamp += f"|map:{_stamp(Path(joint_map), None, '')}"
        if r.get("user_files"):
            stamp += f"|split:{r['split']}|up:{up}"  # the split is written into the clip's meta
            if asf is not None and str(r["file"]).lower().endswith((".amc", ".amc.gz")):
                stamp += f"|asf:{_stamp(Path(asf), None, '')}"
        entry["stamp"] = stamp
        prev = old.get(cid)
        if prev and prev.get("stamp") == stamp and (cache / rel_out).is_file():
            clips[cid] = prev
            continue
        clips[cid] = entry
        todo.append({**r, "file": str(r["file"]), "id": cid, "out": str(cache / rel_out), "fps": fps,
                     "rest_joints": rest_list, "rest_source": rest_source,
                     "joint_map": str(joint_map) if joint_map is not None else None,
                     "asf": str(asf) if asf is not None else None, "up": up})
    skipped = len(clips) - len(todo)

    def finish(res: dict[str, Any]) -> None:
        cid = res["id"]
        if res["ok"]:
            clips[cid].update({k: res[k] for k in ("frames", "fps", "seconds", "skeleton", "lowest_foot_y")})
        else:
            failures[cid] = res["error"]
            clips.pop(cid, None)

    n_workers = workers if workers is not None else min(2, os.cpu_count() or 1)
    # start-up: rich.progress adds ~40 ms to import wearpose.motion
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    columns = (TextColumn("[bold]preparing motion corpus"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
               TimeRemainingColumn())
    with Progress(*columns, disable=not progress or not todo, transient=False) as bar:
        task = bar.add_task("convert", total=len(todo))
        if n_workers <= 1 or len(todo) <= 1:
            for job in todo:
                finish(_convert_one(job))
                bar.advance(task)
        else:
            # Biggest files first so that the two workers finish together.
            todo.sort(key=lambda j: -Path(j["file"]).stat().st_size)
            # "spawn": forking a parent that already ran torch can deadlock its OpenMP pool.
            with ProcessPoolExecutor(max_workers=n_workers, mp_context=multiprocessing.get_context("spawn")) as ex:
                futures = [ex.submit(_convert_one, job) for job in todo]
                for fut in as_completed(futures):
                    finish(fut.result())
                    bar.advance(task)

    write_index(cache, clips, failures, corpus=provenance, converter=CONVERTER_VERSION, fps=fps,
                rest_joints=rest_list, rest_source=rest_source)
    return {"converted": len(todo) - sum(1 for j in todo if j["id"] in failures), "skipped": skipped,
            "failed": len(failures), "failures": failures, "seconds": time.perf_counter() - t0, "index": str(index_path),
            "store": {"path": str(cache.resolve()), "converter": CONVERTER_VERSION, "corpus": provenance}}


class CorpusStore:
    """Read access to a prepared cache (:func:`prepare_corpus`).

    Args:
        cache_dir: the cache (default :func:`wearpose.motion.paths.cache_dir`).

    Raises:
        InputFileError: no (valid) ``index.json`` in the cache.
    """

    def __init__(self, cache_dir: str | Path | None = None):
        self.root = default_cache_dir(cache_dir)
        path = self.root / INDEX_NAME
        if not path.is_file():
            raise InputFileError(path, "no prepared corpus index", "an index.json written by prepare_corpus (run it first)")
        try:
            index = json.loads(path.read_text(encoding="utf-8"))
        except ValueError as exc:
            raise InputFileError(path, f"invalid JSON ({exc})", "an index.json written by prepare_corpus") from exc
        if index.get("format") != "wearpose.motion.index" or index.get("version") != INDEX_VERSION:
            raise InputFileError(path, f"format {index.get('format')!r} version {index.get('version')!r}",
                                 f"format 'wearpose.motion.index' version {INDEX_VERSION}", field="format")
        self.index = index
        self.entries: dict[str, dict[str, Any]] = index["clips"]
        self.failures: dict[str, str] = index.get("failures", {})
        #: The sources this store is restricted to (:meth:`subset`), None for the whole store.
        self.sources_only: tuple[str, ...] | None = None

    def __len__(self) -> int:
        return len(self.entries)

    def clips(self, split: str | Iterable[str] | None = None, source: str | Iterable[str] | None = None,
              licence: str | Iterable[str] | None = None) -> list[str]:
        """Sorted clip ids, optionally filtered (each filter: one value or several)."""
        def ok(value: str, f: str | Iterable[str] | None) -> bool:
            return f is None or (value == f if isinstance(f, str) else value in set(f))
        return sorted(cid for cid, e in self.entries.items()
                      if ok(e["split"], split) and ok(e["source"], source) and ok(e["licence"], licence))

    def sources(self) -> list[str]:
        """The sources of the clips, sorted (``["bandai", "cmu_asf", "cmu_daz"]``)."""
        return sorted({e["source"] for e in self.entries.values()})

    def subset(self, source: str | Iterable[str]) -> CorpusStore:
        """This store restricted to the clips of ``source`` (one name or several): the same
        files, an index of only those clips, so every reader of the store (training data,
        evaluation protocols) sees one lab's clips. Its :meth:`provenance` names the sources.

        Raises:
            ConfigError: a source the store does not hold (the message lists those it does).
        """
        want = {source} if isinstance(source, str) else set(source)
        unknown = sorted(want - set(self.sources()))
        if unknown:
            raise ConfigError(f"corpus store {self.root}: no clips of source {', '.join(map(repr, unknown))}; "
                              f"expected one of {', '.join(self.sources())}")
        view = copy.copy(self)
        view.entries = {cid: e for cid, e in self.entries.items() if e["source"] in want}
        view.sources_only = tuple(sorted(want))
        return view

    def entry(self, clip_id: str) -> dict[str, Any]:
        """The index row of ``clip_id`` (KeyError naming the id if absent)."""
        try:
            return self.entries[clip_id]
        except KeyError:
            raise KeyError(f"clip {clip_id!r} is not in the prepared corpus at {self.root}") from None

    def load(self, clip_id: str, dtype: torch.dtype = torch.float32) -> MotionSequence:
        """The clip's :class:`MotionSequence`."""
        return MotionSequence.load(self.root / self.entry(clip_id)["file"], dtype=dtype)

    def provenance(self) -> dict[str, Any]:
        """Which store and which corpus version results come from: ``{"path"`` (the store),
        ``"converter"`` (its conversion version), ``"corpus"`` (:func:`prepare_corpus`'s record:
        a manifest corpus's path, name and manifest SHA-1, or users' folders with their split and
        source; ``None`` for stores prepared before it was recorded)``}``, and ``"sources"`` for a
        :meth:`subset`. Evaluation results carry it."""
        out = {"path": str(self.root.resolve()), "converter": self.index.get("converter"),
               "corpus": self.index.get("corpus")}
        if self.sources_only is not None:
            out["sources"] = list(self.sources_only)
        return out

    def summary(self) -> dict[str, Any]:
        """Counts and minutes: ``{"clips", "subjects", "minutes", "minutes_per_split",
        "minutes_per_source", "minutes_per_licence", "clips_per_split", "frame_rates", "failures",
        "floor_suspect"}`` (the last: ids of clips whose lowest foot joint is more than
        :data:`FLOOR_TOLERANCE_M` from y = 0)."""
        def add(d: dict[str, float], k: str, v: float) -> None:
            d[k] = d.get(k, 0.0) + v
        per_split: dict[str, float] = {}
        per_source: dict[str, float] = {}
        per_lic: dict[str, float] = {}
        n_split: dict[str, float] = {}
        rates: dict[str, float] = {}
        for e in self.entries.values():
            m = float(e.get("seconds", 0.0)) / 60.0
            add(per_split, e["split"], m)
            add(per_source, e["source"], m)
            add(per_lic, e["licence"], m)
            add(n_split, e["split"], 1)
            add(rates, f"{float(e.get('fps', 0)):g}", 1)
        r = lambda d: {k: round(v, 2) for k, v in sorted(d.items())}  # noqa: E731
        suspect = sorted(cid for cid, e in self.entries.items()
                         if e.get("lowest_foot_y") is not None and abs(float(e["lowest_foot_y"])) > FLOOR_TOLERANCE_M)
        return {"clips": len(self.entries), "subjects": len({(e["source"], e["subject"]) for e in self.entries.values()}),
                "minutes": round(sum(per_split.values()), 2), "minutes_per_split": r(per_split),
                "minutes_per_source": r(per_source), "minutes_per_licence": r(per_lic),
                "clips_per_split": {k: int(v) for k, v in sorted(n_split.items())},
                "frame_rates": {k: int(v) for k, v in sorted(rates.items())}, "failures": len(self.failures),
                "floor_suspect": suspect, "store": self.provenance()}

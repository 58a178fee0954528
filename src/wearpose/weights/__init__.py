"""Trained weights shipped with wearpose, each ``<name>.pt`` with a ``<name>.json`` card.

A card says what the weights are, the exact command that trained them, the training data (clip
split, sources and their licences), the measured metrics and the file size. Weights trained on
CC BY-NC clips are for non-commercial use only; the card's ``licence`` field says so.

``archive/`` keeps weights that were shipped before and are no longer (``<name>_v1.pt`` with
their cards): the starting points of the recipes that fine-tune from them and the "before" of
the before/after tables. :func:`archived_path` finds one; they are not in :func:`list_weights`.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from wearpose.errors import ConfigError

WEIGHTS_DIR = Path(__file__).parent


def list_weights() -> tuple[str, ...]:
    """Names of the shipped weights (those with both a ``.pt`` and a ``.json`` card)."""
    return tuple(sorted(p.stem for p in WEIGHTS_DIR.glob("*.pt") if p.with_suffix(".json").is_file()))


def weight_path(name: str) -> Path:
    """Path of shipped weights ``name`` (ConfigError listing what is shipped if absent)."""
    p = WEIGHTS_DIR / f"{name}.pt"
    if not p.is_file() or not p.with_suffix(".json").is_file():
        raise ConfigError(f"no shipped weights {name!r}; available: {', '.join(list_weights()) or 'none'}")
    return p


def archived_path(name: str) -> Path:
    """Path of archived weights ``archive/<name>.pt`` (module doc); ConfigError listing the archive if absent."""
    p = WEIGHTS_DIR / "archive" / f"{name}.pt"
    if not p.is_file():
        have = sorted(q.stem for q in (WEIGHTS_DIR / "archive").glob("*.pt"))
        raise ConfigError(f"no archived weights {name!r}; archived: {', '.join(have) or 'none'}")
    return p


def card(name: str) -> dict[str, Any]:
    """The JSON card of shipped weights ``name``."""
    return json.loads(weight_path(name).with_suffix(".json").read_text())

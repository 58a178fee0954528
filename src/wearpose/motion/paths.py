"""Where the motion corpus and the prepared cache live (one place; the CLI calls these)."""

from __future__ import annotations

import os
from pathlib import Path

from wearpose.errors import ConfigError


def _walk_up_for_data(start: Path) -> Path | None:
    """First ``<ancestor>/../shared/data`` (a checkout's sibling ``shared/data``) above ``start``."""
    for d in (start, *start.parents):
        for cand in (d / "shared" / "data", d.parent / "shared" / "data"):
            if cand.is_dir():
                return cand
    return None


def data_dir(explicit: str | Path | None = None, must_exist: bool = True) -> Path:
    """The motion corpus directory.

    Order: ``explicit``; ``$WEARPOSE_DATA``; ``../shared/data`` next to the repository checkout,
    found by walking up from the current directory and then from this package's directory.

    Raises:
        ConfigError: nothing found (or the chosen directory does not exist) and ``must_exist``.
    """
    if explicit is not None:
        p = Path(explicit).expanduser()
        source = "the given data directory"
    elif os.environ.get("WEARPOSE_DATA"):
        p = Path(os.environ["WEARPOSE_DATA"]).expanduser()
        source = "$WEARPOSE_DATA"
    else:
        found = _walk_up_for_data(Path.cwd().resolve()) or _walk_up_for_data(Path(__file__).resolve().parent)
        if found is None:
            if must_exist:
                raise ConfigError("motion corpus not found: set WEARPOSE_DATA to the folder holding manifest.csv "
                                  "(default: ../shared/data next to the wearpose checkout)")
            return Path("../shared/data")
        return found
    if must_exist and not p.is_dir():
        raise ConfigError(f"{source} = {p} is not a directory; expected the motion corpus folder (with manifest.csv)")
    return p


def cache_dir(explicit: str | Path | None = None) -> Path:
    """The prepared-corpus cache: ``explicit``, ``$WEARPOSE_CACHE``, else ``~/.cache/wearpose``
    (``$XDG_CACHE_HOME/wearpose`` when that is set). Not created here."""
    if explicit is not None:
        return Path(explicit).expanduser()
    if os.environ.get("WEARPOSE_CACHE"):
        return Path(os.environ["WEARPOSE_CACHE"]).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "wearpose"

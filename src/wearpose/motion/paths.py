"""Where the motion corpus and the prepared cache live (one place; the CLI calls these)."""

from __future__ import annotations

import os
from pathlib import Path

from wearpose.errors import ConfigError


#: The corpus folder looked for beside a checkout (``<parent>/shared/<name>``): corpus v2.
DEFAULT_CORPUS = "data-v2"
#: Older corpus folders: found only to say so in the error (never used silently: a store built
#: from them would not be the default corpus).
OLDER_CORPORA = ("data",)


def _walk_up_for(start: Path, name: str) -> Path | None:
    """First ``<ancestor>/shared/<name>`` or ``<ancestor>/../shared/<name>`` (a checkout's
    sibling ``shared/``) above ``start``."""
    for d in (start, *start.parents):
        for cand in (d / "shared" / name, d.parent / "shared" / name):
            if cand.is_dir():
                return cand
    return None


def _find(name: str) -> Path | None:
    return _walk_up_for(Path.cwd().resolve(), name) or _walk_up_for(Path(__file__).resolve().parent, name)


def data_dir(explicit: str | Path | None = None, must_exist: bool = True) -> Path:
    """The motion corpus directory.

    Order: ``explicit``; ``$WEARPOSE_DATA``; ``../shared/data-v2`` (corpus v2) next to the
    repository checkout, found by walking up from the current directory and then from this
    package's directory.

    Raises:
        ConfigError: nothing found (or the chosen directory does not exist) and ``must_exist``;
            when only an older corpus (``../shared/data``, v1) is found, the message says so
            and how to use it.
    """
    if explicit is not None:
        p = Path(explicit).expanduser()
        source = "the given data directory"
    elif os.environ.get("WEARPOSE_DATA"):
        p = Path(os.environ["WEARPOSE_DATA"]).expanduser()
        source = "$WEARPOSE_DATA"
    else:
        found = _find(DEFAULT_CORPUS)
        if found is None:
            if must_exist:
                older = next((o for o in map(_find, OLDER_CORPORA) if o is not None), None)
                hint = (f"; found the older corpus {older} (v1): set WEARPOSE_DATA={older} to use it" if older else "")
                raise ConfigError(f"motion corpus not found: expected ../shared/{DEFAULT_CORPUS} next to the wearpose "
                                  f"checkout, or WEARPOSE_DATA set to the folder holding manifest.csv{hint}")
            return Path("..") / "shared" / DEFAULT_CORPUS
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

"""A private mini corpus store (3 short real clips) for the recording-set tests.

Copied from the prepared corpus (``$WEARPOSE_CACHE`` / ``~/.cache/wearpose``) when it exists, else
prepared from the shared motion data (``$WEARPOSE_DATA``); tests skip when neither is there.
A private copy keeps the tests independent of the user's store and lets them break a clip.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest


def make_mini_store(root: Path) -> tuple[Path, list[str]]:
    """``(cache_dir, clip_ids)``: a store with the shortest NonCommercial clip and the two
    shortest other clips of the corpus (or whatever 3 clips could be prepared)."""
    from wearpose.errors import WearposeError
    from wearpose.motion import CorpusStore, data_dir, prepare_corpus
    from wearpose.recording.dataset import is_noncommercial

    try:
        store = CorpusStore()
    except (WearposeError, OSError):
        try:
            src = data_dir()
        except WearposeError:
            pytest.skip("motion corpus absent: no prepared store (run `wearpose data prepare`) and no data "
                        "(set WEARPOSE_DATA); the recording-set tests need 3 real clips")
        prepare_corpus(src, root / "prepared", limit=3, workers=1, progress=False)
        store = CorpusStore(root / "prepared")
    by_len = sorted(store.entries, key=lambda c: (float(store.entries[c].get("seconds", 0.0)), c))
    nc = [c for c in by_len if is_noncommercial(store.entries[c].get("licence"))][:1]
    other = [c for c in by_len if not is_noncommercial(store.entries[c].get("licence"))][:3 - len(nc)]
    if len(nc) + len(other) < 3:  # a corpus of one licence kind
        other = [c for c in by_len if c not in nc][:3 - len(nc)]
    ids = sorted(nc + other)
    cache = root / "mini_store"
    for cid in ids:
        f = cache / store.entries[cid]["file"]
        f.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(store.root / store.entries[cid]["file"], f)
    index = dict(store.index)
    index["clips"] = {cid: store.entries[cid] for cid in ids}
    index["failures"] = {}
    (cache / "index.json").write_text(json.dumps(index))
    return cache, ids

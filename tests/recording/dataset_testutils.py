"""A private mini corpus store (3 short real clips) for the recording-set tests.

Copied from the session's corpus store (the ``corpus_root`` fixture of ``tests/conftest.py``):
a private copy lets a test break a clip without touching the store other tests read.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path



def make_mini_store(root: Path, source: Path) -> tuple[Path, list[str]]:
    """``(cache_dir, clip_ids)``: a store in ``root`` with the shortest NonCommercial clip and the
    two shortest other clips of the prepared store ``source``."""
    from wearpose.motion import CorpusStore
    from wearpose.recording.dataset import is_noncommercial

    store = CorpusStore(source)
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

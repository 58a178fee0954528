"""One per-clip seed for every method (wearpose.estimators.seeding): the seeds of the old
per-method copies, bit for bit."""

import zlib

from wearpose.estimators.seeding import clip_seed


def test_clip_seed_pinned_values():
    # Values of the former empose.data.clip_seed / birae.data.clip_seed at commit 578713e.
    assert clip_seed("cmu_daz/05/05_01", 0) == 928069312
    assert clip_seed("cmu_daz/05/05_01", 3, "eval") == 1175462583
    assert clip_seed("sitting/train/0000", 0, "pip-sitting") == 11577491
    # BiRAE's namespaces are prefixed "birae:" (its old copy hashed "birae:<namespace>:<id>").
    assert clip_seed("cmu_daz/05/05_01", 0, "birae:train") == 1911142757
    assert clip_seed("cmu_daz/05/05_01", 2, "birae:val") == 1819240482
    assert clip_seed("x", 0, "birae:demo-noise") == 881047691


def test_clip_seed_matches_the_former_formulas():
    ids = [f"src/{i:02d}/{i:02d}_{j:02d}" for i in range(7) for j in range(3)]
    for cid in ids:
        for seed in (0, 1, 5, 123456):
            for ns in ("train", "val", "eval", "pip", "miposer"):
                empose = (zlib.crc32(f"{ns}:{cid}".encode()) + 7919 * seed) % (2 ** 31 - 1)
                birae = (zlib.crc32(f"birae:{ns}:{cid}".encode()) + 7919 * seed) % (2 ** 31 - 1)
                assert clip_seed(cid, seed, ns) == empose
                assert clip_seed(cid, seed, f"birae:{ns}") == birae
    assert 0 <= clip_seed("a", 10 ** 9) < 2 ** 31 - 1
    assert clip_seed("a", 0, "train") != clip_seed("a", 0, "eval")

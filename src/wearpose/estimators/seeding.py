"""Per-clip seeds of the estimators' simulated data (training, validation, evaluation, demos).

One function, :func:`clip_seed`, for every method: a clip's draws depend on its id, the run's
base seed and a ``namespace`` ("train", "eval", "pip-sitting", "birae:train", ...), never on
the clip's position in a run, so data are deterministic and training draws never repeat
evaluation draws. A method that wants seeds of its own prefixes its namespaces (BiRAE uses
``"birae:<namespace>"``).

Not the same scheme as :func:`wearpose.recording.dataset.clip_seed` (a 48-bit sha256 of the
base seed and the clip id, the seeds ``wearpose simulate`` records in its dataset files): the
two are kept apart so the seeds of already written datasets and trained models stay as they
were.
"""

from __future__ import annotations

import zlib

#: The seed range: a positive 31-bit integer (torch, numpy and ``random`` all take it).
SEED_MODULUS = 2 ** 31 - 1


def clip_seed(clip_id: str, seed: int, namespace: str = "train") -> int:
    """Deterministic seed of clip ``clip_id`` for base ``seed`` in ``namespace``.

    ``(crc32("<namespace>:<clip_id>") + 7919 * seed) mod (2^31 - 1)``: the scheme every shipped
    model's training data and every committed evaluation table were drawn with.
    """
    return (zlib.crc32(f"{namespace}:{clip_id}".encode()) + 7919 * int(seed)) % SEED_MODULUS

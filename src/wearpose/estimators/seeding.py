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

The networks' own draws come from two more seeds of the same base seed (a run is a function of
its seed, issue 24): :func:`seeded` wraps the construction of a network so its initial weights
are drawn from :func:`init_seed` (not from torch's global generator, whose state differs run to
run), and the training loop re-seeds torch's global generator from :func:`step_seed` before
every optimiser step, so dropout masks depend on the seed and the step only (a resumed run
draws what the uninterrupted one drew).
"""

from __future__ import annotations

import contextlib
import zlib
from typing import Iterator

#: The seed range: a positive 31-bit integer (torch, numpy and ``random`` all take it).
SEED_MODULUS = 2 ** 31 - 1


def clip_seed(clip_id: str, seed: int, namespace: str = "train") -> int:
    """Deterministic seed of clip ``clip_id`` for base ``seed`` in ``namespace``.

    ``(crc32("<namespace>:<clip_id>") + 7919 * seed) mod (2^31 - 1)``: the scheme every shipped
    model's training data and every committed evaluation table were drawn with.
    """
    return (zlib.crc32(f"{namespace}:{clip_id}".encode()) + 7919 * int(seed)) % SEED_MODULUS


def init_seed(seed: int) -> int:
    """Seed of a network's initial weights for base ``seed`` (:func:`seeded`)."""
    return clip_seed("weights", seed, "init")


def step_seed(seed: int, step: int) -> int:
    """Seed of torch's global generator for optimiser step ``step`` (0-based) of a run with base
    ``seed``: dropout masks and any other draw of the network in that step."""
    return (zlib.crc32(f"step:{int(step)}".encode()) + 7919 * int(seed)) % SEED_MODULUS


@contextlib.contextmanager
def seeded(seed: int) -> Iterator[None]:
    """Run the block with torch's CPU generator seeded by ``seed``, restoring its state after.

    For building a network: ``with seeded(init_seed(cfg.seed)): model = Net(cfg)`` gives the
    same initial weights in every process, and the caller's own random stream is left as it was.
    Networks are built on the CPU (moved to their device afterwards), so only the CPU generator
    is forked.
    """
    import torch  # start-up: torch adds ~1.4 s (1038 modules) to this torch-free module

    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(int(seed))
        yield

"""EM-POSE optimisation baseline (L-BFGS + our pose-prior VAE) against the LGD-RNN on a subset of
the held-out test split (an optimisation per frame is slow: clips and frames are subsampled).

Run::

    python benchmarks/empose_lbfgs.py --prior runs/poseprior_cpu/prior.pt \\
        --lgd src/wearpose/weights/empose12_cpu.pt --clips 6 --every 10

Both models see the same simulated recordings (Table 2 protocol: default EM noise, held-out
random subject offsets); the L-BFGS tracker solves every ``--every``-th frame (warm-started from
the previous solved frame) and only those frames are scored, for both models. Writes
``benchmarks/results/empose_lbfgs.md`` and ``.json``.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import time
from pathlib import Path

import torch


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--prior", required=True)
    ap.add_argument("--lgd", default="src/wearpose/weights/empose12_cpu.pt")
    ap.add_argument("--clips", type=int, default=6, help="test clips, spread evenly over the sorted split")
    ap.add_argument("--every", type=int, default=10)
    ap.add_argument("--max-iter", type=int, default=20)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "empose_lbfgs"))
    a = ap.parse_args(argv)
    torch.set_num_threads(a.threads)
    from wearpose.estimators.empose.evaluate import evaluate_models, table2_markdown
    from wearpose.estimators.empose.estimator import EmposeEstimator
    from wearpose.estimators.empose.optimization import LbfgsEstimator
    from wearpose.motion import CorpusStore

    lb = LbfgsEstimator.load(a.prior)
    lb.every, lb.max_iter = a.every, a.max_iter
    lgd = EmposeEstimator.load(a.lgd)

    class Subsampled:  # the LGD-RNN scored on the same frames as the tracker
        def __init__(self, est: EmposeEstimator) -> None:
            self.__dict__["_e"] = est

        def __getattr__(self, k: str):
            return getattr(self._e, k)

        def estimate(self, rec):
            t = self._e.estimate(rec)
            t.valid = t.valid & (torch.arange(len(t.valid)) % a.every == 0)
            return t

    store = CorpusStore()
    ids = store.clips(split="test")
    pick = [ids[round(i * (len(ids) - 1) / max(1, a.clips - 1))] for i in range(a.clips)]

    class Subset:
        def clips(self, split=None):
            return pick

        def load(self, cid):
            return store.load(cid)

    t0 = time.time()
    res = evaluate_models({"LGD-RNN": Subsampled(lgd), "L-BFGS + VAE prior": lb}, "test", store=Subset(),
                          progress=lambda d, t: print(f"  {d}/{t} clips ({time.time() - t0:.0f} s)", file=sys.stderr))
    res.update(command="python " + shlex.join([sys.argv[0], *(argv if argv is not None else sys.argv[1:])]),
               clip_ids=pick, every=a.every, max_iter=a.max_iter, wall_seconds=time.time() - t0,
               time_utc=time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()))
    tab = table2_markdown(res)
    md = ["# EM-POSE optimisation baseline (subset of the test split)", "",
          f"Produced by `{res['command']}`.", "", tab, "",
          f"Subset: {len(pick)} test clips spread over the sorted split ({', '.join(pick)}); every {a.every}th frame "
          f"scored (the L-BFGS tracker solves only those, warm-started from the previous solved frame, at most "
          f"{a.max_iter} L-BFGS iterations with strong-Wolfe line search per frame). Pose prior: our PosePriorVAE "
          "(VPoser is unavailable), checkpoint `" + a.prior + "`. Estimate time [s]: "
          + ", ".join(f"{n} {m['seconds']:.0f}" for n, m in res["models"].items()) + "."]
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".md").write_text("\n".join(md) + "\n", encoding="utf-8")
    out.with_suffix(".json").write_text(json.dumps(res, indent=2, default=str) + "\n", encoding="utf-8")
    print("\n".join(md))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

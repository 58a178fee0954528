"""EM-POSE two-stage with the paper's stage 2: build the checkpoint for the Table 10 row "2-stage, paper LGD IK +
site mapper". Two-stage with the paper's LGD IK as stage 2 (from runs/twostage12_long, trained on noisy GT joints,
independent of the mapper) behind the site-input mapper of the shipped empose12_twostage_cpu. No training:
every tensor comes from one of the two checkpoints (checked: the LGD IK tensors are unchanged by the second copy).

Run: ``python benchmarks/empose_twostage_lgdik.py [OUT.pt]`` (needs runs/twostage12_long/best.pt, see the Table 10
note for its command), then ``benchmarks/empose_table10.py --ckpt NAME=OUT.pt``.
"""
from __future__ import annotations

import sys

import torch

from wearpose.estimators.checkpoint import load_checkpoint
from wearpose.estimators.empose.config import EmposeConfig
from wearpose.estimators.empose.twostage import TwoStageEstimator, warm_start

LGD_IK = "runs/twostage12_long/best.pt"  #: ik="lgd" run: its stage 2 is the paper's LGD IK
MAPPER = "src/wearpose/weights/empose12_twostage_cpu.pt"  #: mapper_input="site" mapper


def main() -> int:
    torch.set_num_threads(1)
    out = sys.argv[1] if len(sys.argv) > 1 else "runs/twostage12_lgdik_site.pt"
    cfg = EmposeConfig.from_dict(load_checkpoint(LGD_IK).config).override(mapper_input="site", ik="lgd")
    est = TwoStageEstimator(cfg)
    warm_start(est, LGD_IK)
    ik_before = {k: v.clone() for k, v in est.model.state_dict().items() if k.startswith("ik.")}
    warm_start(est, MAPPER)
    if not ik_before or any(not torch.equal(v, est.model.state_dict()[k]) for k, v in ik_before.items()):
        raise SystemExit("the LGD IK stage was not taken intact from " + LGD_IK)
    est.meta["note"] = f"mapper of {MAPPER} (site inputs) + LGD IK stage 2 of {LGD_IK}"
    print(est.save(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

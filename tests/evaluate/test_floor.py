"""wearpose.evaluate.floor: where a placed estimate stands against the truth, per floor rule."""

from __future__ import annotations

from pathlib import Path

import pytest

RUN = "bandai/bandai-B/dataset-2_run_youthful_005"  # a held-out run (test split), in the session's store


@pytest.mark.corpus
def test_contact_frames_keep_a_run_out_of_the_floor(corpus_root: Path) -> None:
    """A run is in the air for most of its frames: the median lowest point over every frame (the
    rule before) puts the shipped EM-POSE 12's stance feet more than 5 cm into the floor; the
    contact frames' median (what ``wearpose estimate`` does) keeps every frame above -5 cm and
    no standing frame more than 5 cm into it. Its figures for the whole split are in
    benchmarks/results/floor_contact_empose_test.md."""
    from wearpose.estimators.run import CONTACT_SPEED_M_S, open_model
    from wearpose.evaluate.floor import floor_placement, rule_name
    from wearpose.motion import CorpusStore

    res = floor_placement(open_model("empose12_cpu"), CorpusStore(corpus_root), "test", [RUN],
                          rules=(None, CONTACT_SPEED_M_S))
    assert res["excluded"] == [] and res["per_clip"][0]["floor"] == "median lowest point of the contact frames on y = 0"
    every, contact = res["rules"]["every frame"], res["rules"][rule_name(CONTACT_SPEED_M_S)]
    assert every["lowest_cm"] < -5.0 and every["clips_under"] == 1, every
    assert contact["lowest_cm"] > -5.0 and contact["clips_under"] == 0 and contact["standing_sink_pct"] == 0.0, contact
    assert abs(every["median_abs_cm"] - contact["median_abs_cm"]) < 2.0  # one shift of the same estimate


def test_summary_counts_what_a_user_sees() -> None:
    """Standing frames off by more than 5 cm either way, any frame more than 5 cm under the floor;
    a frame 6 cm over the truth in mid-air is neither."""
    import torch

    from wearpose.evaluate.floor import FloorFrames, _summary

    e = torch.tensor([-0.06, 0.0, 0.06, 0.06, 0.0])
    standing = torch.tensor([True, True, True, False, True])
    height = torch.tensor([-0.055, 0.01, 0.07, 0.30, -0.02])
    s = _summary(FloorFrames(e, standing, height))
    assert s["standing_sink_pct"] == pytest.approx(20.0) and s["standing_float_pct"] == pytest.approx(20.0)
    assert s["under_floor_pct"] == pytest.approx(20.0) and s["lowest_cm"] == pytest.approx(-5.5)
    assert (s["worst_standing_sink_cm"], s["worst_standing_float_cm"]) == (pytest.approx(-6.0), pytest.approx(6.0))

"""The ``wearpose`` command: help examples, JSON output, errors and the round-trip demo."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from wearpose.cli import app

runner = CliRunner()


@pytest.mark.parametrize("cmd", [["info"], ["demo"], ["view"], ["export"], ["data", "prepare"], ["data", "info"]])
def test_every_command_has_an_example(cmd: list[str]) -> None:
    res = runner.invoke(app, [*cmd, "--help"])
    assert res.exit_code == 0, res.output
    assert "Example: wearpose" in res.output


def test_info_json_reports_the_embedded_asset(tmp_path: Path) -> None:
    res = runner.invoke(app, ["info", "--json"], env={"WEARPOSE_CACHE": str(tmp_path / "nostore")})
    assert res.exit_code == 0, res.output
    info = json.loads(res.output)
    assert info["body"]["asset_id"] == "wearpose-anny-v1"
    assert 1.60 <= info["body"]["rest_height_m"] <= 1.80
    assert info["body"]["joints"] == 24 and info["body"]["shape_dims"] == 10
    assert "CC0" in info["body"]["licence"]
    assert info["corpus"]["prepared"] is False and "wearpose data prepare" in info["corpus"]["reason"]


@pytest.mark.corpus
def test_data_prepare_and_info_on_a_few_clips(tmp_path: Path, corpus_root: Path) -> None:
    env = {"WEARPOSE_CACHE": str(tmp_path / "store")}
    res = runner.invoke(app, ["data", "prepare", "--limit", "3", "--workers", "1", "--json"], env=env)
    assert res.exit_code == 0, res.output
    assert json.loads(res.output)["converted"] == 3
    res = runner.invoke(app, ["data", "info", "--json"], env=env)
    summary = json.loads(res.output)
    assert summary["clips"] == 3 and summary["minutes"] > 0


@pytest.mark.corpus
def test_demo_round_trip_is_lossless(tmp_path: Path, corpus_store: Path) -> None:
    from wearpose.cli.demo import run_roundtrip_demo

    r = run_roundtrip_demo("cmu_daz/05/05_01", tmp_path, max_seconds=1.0)
    assert r["frames"] == 60
    for route in ("wearpose_npz", "amass_npz"):
        m = r["metrics"][route]
        assert m["mpjpe_mm"] < 0.01 and m["mpjae_deg"] < 0.01 and m["mesh_error_cm"] < 0.001, (route, m)
    assert Path(r["html"]).stat().st_size > 100_000


def test_view_of_a_missing_clip_fails_clearly(tmp_path: Path) -> None:
    res = runner.invoke(app, ["view", str(tmp_path / "nope.bvh"), "--out", str(tmp_path / "v.html")],
                        env={"WEARPOSE_CACHE": str(tmp_path / "nostore")})
    assert res.exit_code != 0
    assert "no such motion" in str(res.exception)


@pytest.mark.corpus
def test_sensor_demo_with_shipped_weights(tmp_path: Path, corpus_store: Path) -> None:
    """The main job: simulated 12 EM sensors on a held-out clip -> shipped LGD-RNN -> pose."""
    from wearpose.cli.demo import run_sensor_demo
    from wearpose.weights import card

    r = run_sensor_demo("cmu_daz/05/05_01", tmp_path, max_seconds=2.0)
    assert r["frames"] == 60 and r["fps"] == 30.0
    # A held-out walk (test split); the card reports ~15 mm MPJPE over the whole test split.
    assert r["metrics"]["mpjpe_mm"] < 40.0, r["metrics"]
    assert r["metrics"]["mpjae_deg"] < 15.0, r["metrics"]
    assert "non-commercial" in card("empose12_cpu")["licence"]
    assert (tmp_path / "recording.npz").is_file() and Path(r["html"]).stat().st_size > 100_000


def test_every_command_and_group_has_an_example() -> None:
    """Walks the whole command tree, so a new command without an example fails here."""
    import typer

    def walk(cmd, path):
        yield path, cmd
        for name, sub in getattr(cmd, "commands", {}).items():
            yield from walk(sub, [*path, name])

    missing = []
    for path, cmd in walk(typer.main.get_command(app), []):
        res = runner.invoke(app, [*path, "--help"])
        assert res.exit_code == 0, (path, res.output)
        if "Example: wearpose" not in " ".join(res.output.replace("│", " ").split()):
            missing.append(" ".join(path) or "(root)")
    assert not missing, f"no 'Example: wearpose ...' in the help of: {missing}"

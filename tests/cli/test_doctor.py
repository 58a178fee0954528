"""``wearpose doctor``: the report's structure, failures turned into lines, exit codes."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from wearpose.cli import app
from wearpose.diagnostics import Check, check_body, check_dependencies, run_checks, summary


def test_dependencies_match_the_pins_of_this_install() -> None:
    deps = {c.name: c for c in check_dependencies()}
    assert {"torch", "numpy", "roma"} <= set(deps)
    assert deps["torch"].status == "ok", deps["torch"]  # 2.13.0+cpu is the pinned release
    assert all(c.status in ("ok", "warn") for c in deps.values() if c.name in ("anny", "ray"))


def test_a_raising_check_becomes_a_fail_line_and_the_others_still_run() -> None:
    def check_broken() -> list[Check]:
        raise RuntimeError("boom")

    def check_fine() -> list[Check]:
        return [Check("x", "fine", "ok", "yes")]

    res = summary(run_checks((check_broken, check_fine)))
    assert res["ok"] is False and res["counts"] == {"ok": 1, "warn": 0, "fail": 1}
    bad = res["checks"][0]
    assert bad["area"] == "broken" and "boom" in bad["detail"] and bad["hint"]


def test_smpl_file_missing_or_bad_is_reported(monkeypatch: pytest.MonkeyPatch, tmp_path) -> None:
    monkeypatch.delenv("WEARPOSE_SMPL_MODEL", raising=False)
    smpl = {c.name: c for c in check_body()}["SMPL model"]
    assert smpl.status == "warn" and "WEARPOSE_SMPL_MODEL" in smpl.hint
    bad = tmp_path / "SMPL_NEUTRAL.npz"
    bad.write_bytes(b"not a model")
    monkeypatch.setenv("WEARPOSE_SMPL_MODEL", str(bad))
    smpl = {c.name: c for c in check_body()}["SMPL model"]
    assert smpl.status == "fail" and str(bad) in smpl.detail


def test_cli_json_report(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("WEARPOSE_SMPL_MODEL", raising=False)
    res = CliRunner().invoke(app, ["doctor", "--json"])
    out = json.loads(res.output)
    assert res.exit_code == (0 if out["ok"] else 1)
    areas = {c["area"] for c in out["checks"]}
    assert {"system", "dependencies", "compute", "body", "data", "weights", "estimators", "optional"} <= areas
    assert all(c["status"] in ("ok", "warn", "fail") for c in out["checks"])
    assert all(c["hint"] for c in out["checks"] if c["status"] != "ok")  # every problem says what to do
    assert "Example: wearpose doctor" in CliRunner().invoke(app, ["doctor", "--help"]).output


def test_every_shipped_weight_passes_including_the_forecaster() -> None:
    """nbeats_cpu (MI-Poser's interference forecaster) is not an estimator checkpoint; doctor used
    to report it as damaged, so a fresh clone failed `wearpose doctor`."""
    from wearpose.diagnostics import check_weights
    from wearpose.weights import list_weights

    checks = {c.name: c for c in check_weights()}
    assert "nbeats_cpu" in list_weights() and set(list_weights()) <= set(checks)
    assert all(c.status == "ok" for c in checks.values()), [c for c in checks.values() if c.status != "ok"]


def test_table_keeps_bracketed_details(monkeypatch: pytest.MonkeyPatch) -> None:
    import wearpose.diagnostics as diag

    bad = Check("weights", "x_cpu", "fail", "x_cpu.pt [format]: not a wearpose checkpoint", "re-install [x]")
    monkeypatch.setattr(diag, "run_checks", lambda *a, **k: [bad])
    res = CliRunner().invoke(app, ["doctor"], env={"COLUMNS": "200"})
    assert res.exit_code == 1 and "[format]" in res.output and "[x]" in res.output

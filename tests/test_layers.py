"""DESIGN.md's module order, as declared in pyproject.toml ([tool.importlinter]): no module
imports one above it, and evaluate's metrics stay low. The second test shows the same checker
refuses an upward import, so the first cannot pass by checking nothing."""

from __future__ import annotations

from pathlib import Path

import pytest
from importlinter.cli import lint_imports

PYPROJECT = Path(__file__).resolve().parents[1] / "pyproject.toml"


def test_no_module_imports_one_above_it(capsys: pytest.CaptureFixture[str]) -> None:
    status = lint_imports(config_filename=str(PYPROJECT), no_cache=True, no_logo=True)
    out = capsys.readouterr().out
    assert status == 0, f"imports against DESIGN.md's order (fix the import, or move the code to its layer):\n{out}"
    assert "DESIGN.md module order KEPT" in out and "metrics stay low" in out


def test_the_checker_refuses_an_upward_import(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    pkg = tmp_path / "layerprobe"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "high.py").write_text("X = 1\n")
    (pkg / "low.py").write_text("def f():\n    from layerprobe.high import X  # inside a function: still seen\n    return X\n")
    cfg = tmp_path / "probe.toml"
    cfg.write_text('[tool.importlinter]\nroot_package = "layerprobe"\n\n[[tool.importlinter.contracts]]\n'
                   'name = "probe order"\ntype = "layers"\nlayers = ["layerprobe.high", "layerprobe.low"]\n')
    monkeypatch.syspath_prepend(str(tmp_path))
    assert lint_imports(config_filename=str(cfg), no_cache=True, no_logo=True) != 0
    assert "layerprobe.low -> layerprobe.high" in capsys.readouterr().out

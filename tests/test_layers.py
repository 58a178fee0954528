"""DESIGN.md's module order, as declared in pyproject.toml ([tool.importlinter]): no module
imports one above it, and evaluate's metrics stay low. The second test shows the same checker
refuses an upward import, so the first cannot pass by checking nothing."""

from __future__ import annotations

import ast
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


# Imports inside functions hide a module's edges from a reader (import-linter still sees them). They
# are kept only where a reason needs them, and the reason is written next to the import (issue 21.6).
INNER_IMPORT_REASONS = ("optional dependency:", "cycle:", "start-up:", "isolation:")
#: Packages (under src/wearpose) held to that rule; the others join as they are cleaned.
INNER_IMPORT_SCOPE = (
    "estimators", "recording", "viewer",
    "motion", "calibration", "stream", "sensors", "geometry", "physics", "export", "body", "interference", "evaluate", "cli",
)
INNER_IMPORT_EXCLUDED: tuple[str, ...] = ()


def undocumented_inner_imports(path: Path) -> list[str]:
    """``path:line: statement`` for each import inside a function of ``path`` without a reason
    (one of :data:`INNER_IMPORT_REASONS`) in a comment on its own line(s) or the line above."""
    lines = path.read_text(encoding="utf-8").splitlines()
    out: list[str] = []

    def documented(node: ast.stmt) -> bool:
        own = lines[node.lineno - 1:node.end_lineno]
        above = [lines[node.lineno - 2]] if node.lineno >= 2 and lines[node.lineno - 2].lstrip().startswith("#") else []
        return any(r in line.split("#", 1)[1] for line in own + above if "#" in line for r in INNER_IMPORT_REASONS)

    def visit(node: ast.AST, in_function: bool) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.Import, ast.ImportFrom)) and in_function and not documented(child):
                out.append(f"{path}:{child.lineno}: {lines[child.lineno - 1].strip()}")
            visit(child, in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)))

    visit(ast.parse("\n".join(lines)), False)
    return out


def test_imports_inside_functions_say_why() -> None:
    src = PYPROJECT.parent / "src" / "wearpose"
    files = sorted([*(p for d in INNER_IMPORT_SCOPE for p in (src / d).rglob("*.py")
                      if not any(p.is_relative_to(src / e) for e in INNER_IMPORT_EXCLUDED)),
                    *src.glob("*.py")])  # and the top-level modules (errors, fileio, diagnostics)
    assert len(files) > 100  # the scope is really scanned
    bad = [hit for p in files for hit in undocumented_inner_imports(p)]
    assert not bad, ("imports inside functions without a reason: move them to the top of the module, or say why on "
                     f"the line above ({' / '.join(r + ' ...' for r in INNER_IMPORT_REASONS)}):\n" + "\n".join(bad))


def test_the_inner_import_check_finds_an_undocumented_one(tmp_path: Path) -> None:
    mod = tmp_path / "probe.py"
    mod.write_text("import os\n\n\ndef f():\n    from wearpose import errors\n    return errors\n\n\n"
                   "def g():\n    # start-up: probe costs 1 ms at import\n    from wearpose import geometry\n"
                   "    import scipy  # optional dependency: probe\n    return geometry, scipy\n\n\n"
                   "def h():\n    # lazily, for speed\n    import json\n    return json\n")
    assert undocumented_inner_imports(mod) == [f"{mod}:5: from wearpose import errors", f"{mod}:18: import json"]

"""Shared fixtures: a hermetic environment, the one corpus fixture, tiny synthetic body assets.

Hermetic: before any test module is imported, ``HOME``, ``XDG_CACHE_HOME`` and ``WEARPOSE_CACHE``
point at a fresh, empty temporary directory (removed at the end), and every test runs in its own
temporary working directory. No test can read a store, weights cache, ``runs/`` or ``out/`` that an
earlier command left on the machine, or write into the checkout. Tests that need the real motion
corpus take the ``corpus_store`` fixture: a small store prepared once per session from
``$WEARPOSE_DATA`` (default ``../shared/data-v2`` beside the checkout) into that directory.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest

from wearpose.body.asset import BodyAsset
from wearpose.body.skeleton import NUM_JOINTS, PARENTS

# SMPL-like rest joints (m), T-pose facing +Z, left at +X.
SMPL_LIKE_REST = np.array([
    [0.00, -0.22, 0.03], [0.06, -0.31, 0.02], [-0.06, -0.31, 0.02], [0.00, -0.11, 0.00],
    [0.10, -0.69, 0.02], [-0.10, -0.69, 0.02], [0.00, 0.03, 0.03], [0.09, -1.09, -0.02],
    [-0.09, -1.09, -0.02], [0.00, 0.08, 0.05], [0.11, -1.15, 0.10], [-0.11, -1.15, 0.10],
    [0.00, 0.29, 0.01], [0.08, 0.19, 0.00], [-0.08, 0.19, 0.00], [0.00, 0.36, 0.05],
    [0.19, 0.23, -0.01], [-0.19, 0.23, -0.01], [0.45, 0.22, -0.03], [-0.45, 0.22, -0.03],
    [0.71, 0.23, -0.01], [-0.71, 0.23, -0.01], [0.80, 0.22, -0.02], [-0.80, 0.22, -0.02],
])


def make_tiny_asset(seed: int = 0, num_betas: int = 10, posedirs: bool = False) -> BodyAsset:
    """A closed tetrahedron around each joint; each vertex skinned to its joint and its parent.

    96 vertices, 96 faces. Joint regressor = tetra centroid, so joints are exactly regressable.
    """
    rng = np.random.default_rng(seed)
    tet = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], dtype=np.float64) * 0.03
    tet_faces = np.array([[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]])
    verts, faces, weights, J_reg = [], [], np.zeros((NUM_JOINTS * 4, NUM_JOINTS)), np.zeros((NUM_JOINTS, NUM_JOINTS * 4))
    for j in range(NUM_JOINTS):
        base = 4 * j
        offs = tet + rng.normal(scale=0.005, size=tet.shape)
        offs -= offs.mean(0)
        verts.append(SMPL_LIKE_REST[j] + offs)
        faces.append(tet_faces + base)
        J_reg[j, base:base + 4] = 0.25
        p = max(PARENTS[j], 0)
        w = rng.uniform(0.6, 1.0, size=4)
        weights[base:base + 4, j] += w
        weights[base:base + 4, p] += 1 - w
    v = np.concatenate(verts)
    shapedirs = rng.normal(scale=0.01, size=(v.shape[0], 3, num_betas))
    pd = rng.normal(scale=0.002, size=((NUM_JOINTS - 1) * 9, v.shape[0] * 3)) if posedirs else None
    return BodyAsset(
        v_template=v.astype(np.float32), faces=np.concatenate(faces).astype(np.int64),
        shapedirs=shapedirs.astype(np.float32), J_regressor=J_reg.astype(np.float32),
        weights=weights.astype(np.float32), parents=np.array(PARENTS, dtype=np.int64),
        posedirs=None if pd is None else pd.astype(np.float32),
        site_names=("head", "left_forearm"), site_vertices=np.array([60, 72]), site_tangent=np.array([61, 73]),
        meta={"asset_id": "tiny-test"},
    )


#: Clips of each split of each source in the session's corpus store: the first ones by clip
#: id, so that ``clips(split=..., source=...)[:n]`` (n <= this) are the full store's clips.
CORPUS_PER_SPLIT = 4
#: Clips that tests name, always in the session's store (each is in the test split).
CORPUS_NAMED = ("cmu_daz/05/05_01", "bandai/bandai-B/dataset-2_walk_feminine_003",
                "bandai/bandai-B/dataset-2_run_youthful_005")

_FRESH: dict[str, str] = {}


def pytest_configure(config: pytest.Config) -> None:  # noqa: ARG001 - pytest hook signature
    """Point the home and every cache at an empty temporary directory, before collection
    (so that nothing computed at import time can see the user's home either)."""
    # Resolve the corpus while the real environment is still in place: a user's
    # WEARPOSE_DATA or the checkout's ../shared/data-v2, never anything in the home.
    from wearpose.motion import data_dir

    try:
        _FRESH["data"] = str(data_dir())
    except Exception as exc:  # noqa: BLE001 - reported by the corpus fixture as a skip reason
        _FRESH["data_error"] = str(exc)
    root = Path(tempfile.mkdtemp(prefix="wearpose-tests-"))
    _FRESH["root"] = str(root)
    (root / "home").mkdir()
    os.environ["HOME"] = str(root / "home")
    os.environ["XDG_CACHE_HOME"] = str(root / "home" / ".cache")
    os.environ["WEARPOSE_CACHE"] = str(root / "home" / ".cache" / "wearpose")
    os.environ["MPLCONFIGDIR"] = str(root / "home" / ".config" / "matplotlib")
    os.environ.setdefault("RAY_AUTH_MODE", "disabled")


def pytest_unconfigure(config: pytest.Config) -> None:  # noqa: ARG001 - pytest hook signature
    if "root" in _FRESH:
        shutil.rmtree(_FRESH["root"], ignore_errors=True)


#: Seconds a test's call may take on 2 cores before the summary names it; slower tests state
#: their own with ``@pytest.mark.budget(seconds)``. The whole suite's budget is in docs/testing.md.
DEFAULT_BUDGET_S = 10.0
_OVER_BUDGET: list[tuple[str, float, float]] = []


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo) -> object:
    yield
    if call.when == "call":
        mark = item.get_closest_marker("budget")
        budget = float(mark.args[0]) if mark else DEFAULT_BUDGET_S
        if call.duration > budget:
            _OVER_BUDGET.append((item.nodeid, call.duration, budget))


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter) -> None:
    """The budget line: every test within its budget, or the ones that were not (a report,
    not a failure: a loaded machine is slower, and speed is measured by benchmarks)."""
    if not _OVER_BUDGET:
        terminalreporter.write_line(f"test-time budget: every test within its budget (default {DEFAULT_BUDGET_S:g} s; "
                                    "slower ones marked @pytest.mark.budget)")
        return
    terminalreporter.section("tests over their time budget", sep="-", yellow=True)
    for nodeid, took, budget in sorted(_OVER_BUDGET, key=lambda r: -r[1]):
        terminalreporter.write_line(f"{took:6.1f} s (budget {budget:g} s)  {nodeid}")


@pytest.fixture(autouse=True)
def _own_working_directory(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Relative paths (a command's default ``runs/``, ``out/``) land in the test's own directory."""
    monkeypatch.chdir(tmp_path)


@pytest.fixture(scope="session")
def corpus_root() -> Path:
    if "data" not in _FRESH:
        pytest.skip(f"motion corpus absent ({_FRESH.get('data_error')}): corpus tests need ../shared/data-v2 "
                    "beside the checkout or WEARPOSE_DATA")
    from wearpose.motion import prepare_corpus

    store = Path(_FRESH["root"]) / "corpus_store"
    res = prepare_corpus(_FRESH["data"], store, per_split=CORPUS_PER_SPLIT, clips=CORPUS_NAMED, workers=1,
                         progress=False)
    assert res["failed"] == 0, res["failures"]
    return store


@pytest.fixture
def corpus_store(corpus_root: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """The session's small prepared store of the real corpus (see ``CORPUS_PER_SPLIT``), also
    made the default store (``$WEARPOSE_CACHE``) for the test, so commands find it as a user's
    ``wearpose data prepare`` would leave it. Skips when the corpus is absent."""
    monkeypatch.setenv("WEARPOSE_CACHE", str(corpus_root))
    return corpus_root


@pytest.fixture(scope="session")
def real_sensors() -> Path:
    """``../shared/real-sensors`` (files logged by real devices, read-only); skips when absent."""
    if "data" not in _FRESH:
        pytest.skip("../shared absent: the real-sensor logs live in ../shared/real-sensors")
    root = Path(_FRESH["data"]).parent / "real-sensors"
    if not root.is_dir():
        pytest.skip(f"{root} absent")
    return root


@pytest.fixture
def one_torch_thread():
    """Run a test with one torch thread: suites of many tiny tensor ops are dominated by
    thread hand-offs on a loaded 2-core machine. Directories opt in from their conftest."""
    import torch

    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


@pytest.fixture
def tiny_asset() -> BodyAsset:
    return make_tiny_asset()

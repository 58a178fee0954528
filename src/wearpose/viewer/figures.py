"""Static PNG figures (matplotlib, headless): the one place that picks the backend and saves.

The demos and method reports (PIP forces/torques, BiRAE uncertainty bands, MI-Poser interference
timeline) draw their own axes and hand the figure here.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any


def pyplot() -> Any:
    """``matplotlib.pyplot`` on the non-interactive Agg backend (no display needed).
    Raises ImportError when matplotlib is missing."""
    import matplotlib  # start-up: matplotlib adds ~210 ms to importing this module

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # start-up: pyplot ~410 ms more, loaded after the Agg backend is set

    return plt


def save_figure(fig: Any, path: str | Path, dpi: int = 90) -> Path:
    """Lay out ``fig``, write it to ``path`` (parent folders created) and close it; returns the path."""
    plt = pyplot()
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path

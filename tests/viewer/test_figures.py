"""Static figures: the shared save path creates folders, writes a PNG and closes the figure."""

from __future__ import annotations

from pathlib import Path

from wearpose.viewer.figures import pyplot, save_figure


def test_save_figure_writes_png_in_new_folder_and_closes(tmp_path: Path) -> None:
    plt = pyplot()
    fig, ax = plt.subplots()
    ax.plot([0, 1], [1, 0])
    out = save_figure(fig, tmp_path / "a" / "b" / "fig.png", dpi=50)
    assert out == tmp_path / "a" / "b" / "fig.png"
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not plt.fignum_exists(fig.number)

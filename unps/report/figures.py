"""Figures of a report: pictures read from run folders, laid out in grids, saved as PNG."""

from __future__ import annotations

from unps.report.collect import METHOD_NAMES, fmt

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from unps.io.files import atomic_path
from unps.report.collect import Run


def pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save(fig, path: Path) -> Path:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110, bbox_inches="tight", metadata={"Software": None})
    pyplot().close(fig)
    return path


def read_rgb(path: Path) -> np.ndarray | None:
    from unps.io.images import read_image

    return read_image(path) if path.exists() else None


def error_picture(folder: Path) -> np.ndarray | None:
    """The run's ``error.npy`` through the error colour map, on the outputs' fixed 0–45° scale."""
    from unps.io.pictures import error_rgb

    path = folder / "error.npy"
    if not path.exists():
        return None
    error = np.load(path).astype(np.float32)
    return error_rgb(error, np.isfinite(error))


def picture_grid(cells: Sequence[Sequence[tuple[str, np.ndarray | None]]], title: str):
    """A figure of rows of titled pictures (None leaves a blank cell), with the error colour bar."""
    import matplotlib
    from unps.io.pictures import ERROR_RANGE_DEG

    plt = pyplot()
    n_rows, n_cols = len(cells), max(len(row) for row in cells)
    fig, axes = plt.subplots(n_rows, n_cols, figsize=(2.2 * n_cols + 0.6, 2.3 * n_rows + 0.4),
                             squeeze=False)
    for r, row in enumerate(cells):
        for c in range(n_cols):
            ax = axes[r][c]
            ax.set_axis_off()
            if c < len(row) and row[c][1] is not None:
                ax.imshow(row[c][1], interpolation="nearest")
                ax.set_title(row[c][0], fontsize=8)
    mappable = matplotlib.cm.ScalarMappable(matplotlib.colors.Normalize(0, ERROR_RANGE_DEG), "viridis")
    bar = fig.colorbar(mappable, ax=axes.ravel().tolist(), fraction=0.02, pad=0.01, extend="max")
    bar.set_label("angular error (°)", fontsize=8)
    fig.suptitle(title, fontsize=10)
    return fig


def qualitative_row(run: Run) -> list[tuple[str, np.ndarray | None]]:
    label = f"{METHOD_NAMES.get(run['method'], run['method'])}, light={run['light']}"
    return [(f"{label}\n{fmt(run['normal_mae'])}°", read_rgb(run.folder / "normals.png")),
            ("error", error_picture(run.folder))]


def read_light_file(path: Path) -> np.ndarray:
    """(n, 3) directions from a ``lights.txt`` written by :func:`unps.lights.write_lights`."""
    return np.loadtxt(path, ndmin=2)[:, :3]

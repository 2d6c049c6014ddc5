"""Pictures people look at: normal maps, error maps, albedo.

Each returns an (H, W, 3) uint8 RGB array (or writes a PNG), black off the mask.
"""

from __future__ import annotations

import io

import numpy as np

ERROR_RANGE_DEG = 45.0


def normal_rgb(normals: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The usual normal-map colours: RGB = (n + 1) / 2, so x → red, y → green, z → blue."""
    rgb = np.round((np.clip(normals, -1, 1) + 1) * 127.5)
    return (rgb * mask[..., None]).astype(np.uint8)


def albedo_rgb(albedo: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, float]:
    """Albedo divided by its maximum over the mask (nothing clipped); returns the image and the scale."""
    scale = float(albedo[mask].max()) if mask.any() else 1.0
    scale = scale if scale > 0 else 1.0
    rgb = np.round(np.clip(albedo / scale, 0, 1) * 255) * mask[..., None]
    return rgb.astype(np.uint8), scale


def error_rgb(error_deg: np.ndarray, mask: np.ndarray, vmax: float = ERROR_RANGE_DEG) -> np.ndarray:
    """Angular error mapped through viridis over [0, vmax] degrees (larger errors get its top colour)."""
    from matplotlib import colormaps

    t = np.clip(np.nan_to_num(error_deg) / vmax, 0, 1)
    rgb = colormaps["viridis"](t)[..., :3] * 255
    return (np.round(rgb) * mask[..., None]).astype(np.uint8)


def error_figure_png(error_deg: np.ndarray, mask: np.ndarray, title: str,
                     vmax: float = ERROR_RANGE_DEG) -> bytes:
    """A PNG of the error map with a labelled colour bar (‘≥ vmax’ at its top) and the title."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    h, w = mask.shape
    shown = np.ma.masked_where(~mask, error_deg)
    fig, ax = plt.subplots(figsize=(4 + 4 * w / max(h, w), 4 * h / max(h, w) + 0.6), dpi=150)
    cmap = matplotlib.colormaps["viridis"].with_extremes(bad="black")
    im = ax.imshow(shown, cmap=cmap, vmin=0, vmax=vmax, interpolation="nearest")
    ax.set_title(title, fontsize=9)
    ax.set_axis_off()
    bar = fig.colorbar(im, ax=ax, extend="max", fraction=0.046, pad=0.04)
    bar.set_label("angular error (°)")
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", bbox_inches="tight")
    plt.close(fig)
    return buffer.getvalue()

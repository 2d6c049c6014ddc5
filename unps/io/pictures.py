"""Pictures people look at: normal maps, error maps, albedo.

Each returns an (H, W, 3) uint8 RGB array (or writes a PNG), black off the mask.
"""

from __future__ import annotations

import io

import numpy as np

ERROR_RANGE_DEG = 45.0


def to_display(values: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Values as uint8 on the display scale of ``reference``: its 99th percentile is white.

    Args:
        values: any shape, linear; reference: the values that set the scale (e.g. the observed
            images on the object).

    >>> to_display(np.array([0.0, 0.5, 1.0, 2.0]), np.array([1.0])).tolist()
    [0, 128, 255, 255]
    """
    level = max(float(np.percentile(reference, 99)), 1e-12)
    return np.round(np.clip(values / level, 0, 1) * 255).astype(np.uint8)


def normal_rgb(normals: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The usual normal-map colours: RGB = (n + 1) / 2, so x → red, y → green, z → blue."""
    rgb = np.round((np.clip(normals, -1, 1) + 1) * 127.5)
    return (rgb * mask[..., None]).astype(np.uint8)


def image_strip(observed: np.ndarray, mask: np.ndarray, normals: np.ndarray | None = None,
                count: int = 7) -> np.ndarray:
    """A strip of ``count`` evenly spaced images (tone-mapped for display) and the normals.

    Args:
        observed: (n, H, W, 3) captured images; mask (H, W) bool; normals (H, W, 3) or None.

    Returns:
        (H, (count + 1)·W, 3) uint8 (count·W without normals).
    """
    picks = np.linspace(0, len(observed) - 1, min(count, len(observed))).astype(int)
    peak = np.percentile(observed[picks][:, mask], 99.5)
    shown = (np.clip(observed[picks] / peak, 0, 1) ** (1 / 2.2) * 255).round().astype(np.uint8)
    tiles = list(shown)
    if normals is not None:
        tiles.append(normal_rgb(normals, mask))
    return np.concatenate(tiles, axis=1)


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


def png_bytes(fig) -> bytes:
    """A matplotlib figure as PNG bytes, cropped to what it draws; the figure is closed."""
    import matplotlib.pyplot as plt

    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", bbox_inches="tight")
    plt.close(fig)
    return buffer.getvalue()


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
    return png_bytes(fig)


def lights_figure_png(directions: np.ndarray, intensities: np.ndarray | None, title: str,
                      true_directions: np.ndarray | None = None) -> bytes:
    """A PNG of every image's light: seen from the camera, the unit hemisphere's (l_x, l_y) with
    one numbered dot per image coloured by its intensity; beside it each image's intensity, and,
    when the true lights are known, each light's direction error with a line to its true place.

    Args:
        directions: (n, 3) unit, unps frame (x right, y up, z toward the camera).
        intensities: (n,) relative intensities, or None when unknown.
        true_directions: (n, 3) unit, the calibrated lights.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(directions)
    fig, (sky, bars) = plt.subplots(1, 2, figsize=(11, 4.6), dpi=130,
                                    gridspec_kw={"width_ratios": [1, 1.3], "wspace": 0.45})
    sky.add_patch(plt.Circle((0, 0), 1, fill=False, color="0.6"))
    for elevation in (30, 60):
        sky.add_patch(plt.Circle((0, 0), np.cos(np.radians(elevation)), fill=False, color="0.85", ls=":"))
    colours = intensities if intensities is not None else np.ones(n)
    if true_directions is not None:
        for est, true in zip(directions, true_directions):
            sky.plot([est[0], true[0]], [est[1], true[1]], color="tab:red", lw=0.7)
        sky.scatter(true_directions[:, 0], true_directions[:, 1], s=22, facecolors="none",
                    edgecolors="tab:green", label="ground truth")
    dots = sky.scatter(directions[:, 0], directions[:, 1], c=colours, cmap="plasma", s=14, zorder=3,
                       label="lights used")
    for i, d in enumerate(directions):
        sky.annotate(str(i + 1), d[:2], fontsize=5, xytext=(2, 2), textcoords="offset points")
    sky.set(xlim=(-1.05, 1.05), ylim=(-1.05, 1.05), aspect="equal", xlabel="l_x (right)",
            ylabel="l_y (up)", title="seen from the camera (rings: elevation 0°, 30°, 60°)")
    sky.title.set_fontsize(9)
    sky.legend(loc="lower left", fontsize=7)
    if intensities is not None:
        fig.colorbar(dots, ax=sky, fraction=0.046, pad=0.04).set_label("intensity")
    index = np.arange(1, n + 1)
    if true_directions is not None:
        cosine = np.clip(np.sum(directions * true_directions, axis=1), -1, 1)
        bars.bar(index, np.degrees(np.arccos(cosine)), color="tab:red")
        bars.set_ylabel("direction error (°)")
    elif intensities is not None:
        bars.bar(index, intensities, color="tab:orange")
        bars.set_ylabel("intensity")
    bars.set_xlabel("image")
    bars.grid(alpha=0.3)
    fig.suptitle(title, fontsize=10)
    return png_bytes(fig)


def centred_height(depth: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, tuple[int, int]]:
    """The (h, w) float64 height over the mask's bounding box, less its mean over the mask, NaN
    off the mask (at least 2 × 2: a line of pixels is padded with NaN), and the box's (top, left)
    corner in the (H, W) ``depth`` and ``mask``.

    Example:
        >>> mask = np.zeros((4, 5), bool); mask[1, 1:4] = True
        >>> height, corner = centred_height(np.arange(20.0).reshape(4, 5), mask)
        >>> height.shape, corner, height[0].tolist()
        ((2, 3), (1, 1), [-1.0, 0.0, 1.0])
    """
    rows, cols = np.nonzero(mask)
    top, bottom, left, right = rows.min(), rows.max() + 1, cols.min(), cols.max() + 1
    height = np.where(mask, depth, np.nan)[top:bottom, left:right].astype(np.float64)
    height = np.pad(height - np.nanmean(height), [(0, max(0, 2 - n)) for n in height.shape],
                    constant_values=np.nan)
    return height, (int(top), int(left))


def shape_figure_png(depth: np.ndarray, mask: np.ndarray, title: str, max_side: int = 56) -> bytes:
    """A PNG of the recovered surface, so that a dome is told from a bowl at a glance: the depth
    seen from above and to the side, shaded by one fixed light, and its profiles along the
    object's middle row and middle column (height toward the camera against position).

    Args:
        depth: (H, W) height toward the camera in pixel units (+z, the unps frame), NaN or
            anything off the mask.
        mask: (H, W) bool, the object.
        title: the figure's title.
        max_side: the 3D view's grid is thinned to at most this many samples a side (the
            profiles keep every pixel).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    height, (top, left) = centred_height(depth, mask)
    stride = max(1, int(np.ceil(max(height.shape) / max_side)))
    thin = height[::stride, ::stride]
    y, x = np.mgrid[0:thin.shape[0], 0:thin.shape[1]] * stride
    fig = plt.figure(figsize=(11, 4.6), dpi=110)
    view = fig.add_subplot(1, 2, 1, projection="3d")
    gy, gx = np.gradient(np.nan_to_num(thin), stride)
    light = np.array([-0.4, 0.5, 0.77])                  # from the upper left, toward the camera
    shade = (-gx * light[0] + gy * light[1] + light[2]) / np.sqrt(1 + gx ** 2 + gy ** 2)
    colours = plt.get_cmap("gray")(np.clip(0.15 + 0.85 * shade, 0, 1))
    view.plot_surface(x, -y, thin, facecolors=colours, rstride=1, cstride=1, linewidth=0,
                      antialiased=False, shade=False)
    span = np.nanmax(thin) - np.nanmin(thin) if np.isfinite(thin).any() else 0.0
    view.set_box_aspect((thin.shape[1], thin.shape[0], max(span / stride, 1.0)))
    view.view_init(elev=30, azim=-60)
    view.set(xlabel="x (pixels)", ylabel="y (pixels)")
    view.set_title("seen from above and to the side", fontsize=9)
    profiles = fig.add_subplot(1, 2, 2)
    fig.subplots_adjust(wspace=0.3)
    middle_row, middle_col = height.shape[0] // 2, height.shape[1] // 2
    profiles.plot(np.arange(height.shape[1]), height[middle_row],
                  label=f"row {top + middle_row} (left → right)")
    profiles.plot(np.arange(height.shape[0]), height[:, middle_col],
                  label=f"column {left + middle_col} (top → bottom)")
    profiles.set(xlabel="position along the line (pixels)", ylabel="height toward the camera (pixels)")
    profiles.set_title("profiles through the middle: a dome bulges up, a bowl sags", fontsize=9)
    profiles.grid(alpha=0.3)
    profiles.legend(fontsize=7)
    fig.suptitle(title, fontsize=10)
    return png_bytes(fig)


def labelled_rows(rows: list[np.ndarray], labels: list[str]) -> np.ndarray:
    """Stack (h, w, 3) uint8 picture rows under one another with each row's label written in a
    dark strip on its left → (Σh, w + strip, 3) uint8.

    Example:
        >>> labelled_rows([np.zeros((40, 50, 3), np.uint8)] * 2, ["observed", "fit"]).shape[0]
        80
    """
    import cv2

    height = min(row.shape[0] for row in rows)
    scale = float(np.clip(height / 90, 0.3, 0.8))
    sizes = [cv2.getTextSize(label, cv2.FONT_HERSHEY_SIMPLEX, scale, 1) for label in labels]
    strip = max(width for (width, _), _ in sizes) + 12
    out = []
    for row, label, ((_, text_height), _) in zip(rows, labels, sizes):
        band = np.full((row.shape[0], strip, 3), 24, np.uint8)
        cv2.putText(band, label, (6, (row.shape[0] + text_height) // 2), cv2.FONT_HERSHEY_SIMPLEX,
                    scale, (235, 235, 235), 1, cv2.LINE_AA)
        out.append(np.concatenate([band, row], 1))
    return np.concatenate(out, 0)

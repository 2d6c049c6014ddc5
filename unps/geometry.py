"""Surfaces from normals: depth by least squares on the gradient field (supplementary Eq. 1), meshes,
and the shadows a depth map casts.

Frame: x right (+col), y up (−row), z toward the camera; orthographic projection with one
unit per pixel of the grid.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.ndimage import binary_dilation, binary_erosion, distance_transform_edt, gaussian_filter
from scipy.sparse.csgraph import connected_components
from scipy.sparse.linalg import spsolve
import torch
import torch.nn.functional as F

from unps.grid import Frame


NO_SLOPE = 1e-6   # |n̄_z| below which a pair of pixels' equation says nothing of their step
SPAN = 1e-3       # weight of Δz = 0 for such a pair: spans a hole in the normals, and only there


def integrate_normals(normals: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Depth whose gradient best agrees with the normals, min_D ‖∇D − Ĝ‖² over the mask.

    Each pair of neighbouring object pixels gives one equation, written with the surface
    orientation constraint rather than the gradient itself so that steep pixels (n_z → 0) do
    not blow up: the step t between them must be orthogonal to their mean normal n̄,
    n̄ · t = 0. Along +col, t = (1, 0, Δz): n̄_z Δz = −n̄_x. Along +row (one pixel down, y − 1),
    t = (0, −1, Δz): n̄_z Δz = n̄_y. A pair whose mean normal says nothing of its step
    (|n̄_z| < :data:`NO_SLOPE`: two pixels without a normal, such as pixels black in every
    image, whose estimated normal is 0; a normal that is not finite counts as none) gets the
    faint :data:`SPAN` · Δz = 0 instead, so that a hole in the normals is spanned from its rim
    rather than left undetermined (a singular system, whose solve is NaN everywhere). The
    sparse normal equations are solved exactly; each connected part of the mask gets zero mean
    depth (depth is known up to an offset).

    Args:
        normals: (H, W, 3) unit normals.
        mask: (H, W) bool.

    Returns:
        (H, W) float32 depth along +z in pixel units, NaN off the mask.
    """
    h, w = mask.shape
    index = -np.ones((h, w), dtype=np.int64)
    index[mask] = np.arange(mask.sum())
    known = np.nan_to_num(normals, nan=0.0, posinf=0.0, neginf=0.0)
    first, second, nz, target = orientation_equations(known, index, mask)
    silent = np.abs(nz) < NO_SLOPE
    nz, target = np.where(silent, SPAN, nz), np.where(silent, 0.0, target)
    m, e = int(mask.sum()), first.size
    eq = np.arange(e)
    a = sp.csr_matrix((np.concatenate([nz, -nz]), (np.concatenate([eq, eq]),
                                                    np.concatenate([second, first]))), shape=(e, m))
    _, part = connected_components(sp.csr_matrix((np.ones(e), (first, second)), shape=(m, m)),
                                   directed=False)
    anchors = np.unique(part, return_index=True)[1]    # one pinned pixel per connected part
    pin = sp.csr_matrix((np.ones(anchors.size), (anchors, anchors)), shape=(m, m))
    z = spsolve((a.T @ a + pin).tocsc(), a.T @ target)
    z -= (np.bincount(part, weights=z) / np.bincount(part))[part]
    depth = np.full((h, w), np.nan, np.float32)
    depth[mask] = z
    return depth


def orientation_equations(normals: np.ndarray, index: np.ndarray, use: np.ndarray
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`integrate_normals`' equations n̄_z (z_second − z_first) = target, one per pair of
    neighbouring pixels (along +col, then along +row) that are both in ``use``.

    Args:
        normals: (H, W, 3) unit normals; index: (H, W) each object pixel's unknown, −1 off it;
        use: (H, W) bool.

    Returns:
        first, second: (e,) the pair's unknowns; nz: (e,) n̄_z; target: (e,) −n̄_x along +col, n̄_y
        along +row.
    """
    h, w = index.shape
    n = normals.astype(np.float64)
    rows, cols, rhs, weights = [], [], [], []
    for (dr, dc), sign in (((0, 1), -1.0), ((1, 0), 1.0)):   # sign: −n_x along col, +n_y along row
        a = index[: h - dr, : w - dc]
        b = index[dr:, dc:]
        ok = (a >= 0) & (b >= 0) & use[: h - dr, : w - dc] & use[dr:, dc:]
        mean = (n[: h - dr, : w - dc] + n[dr:, dc:])[ok] / 2
        component = mean[:, 0] if dc else mean[:, 1]
        rows.append(a[ok])
        cols.append(b[ok])
        weights.append(mean[:, 2])
        rhs.append(sign * component)
    return np.concatenate(rows), np.concatenate(cols), np.concatenate(weights), np.concatenate(rhs)


def continue_surface(normals: np.ndarray, mask: np.ndarray, unseen: np.ndarray,
                     smoothness: float = 1.0, outline: bool = True) -> np.ndarray:
    """``normals`` with the ``unseen`` pixels' replaced by those of the least-curved depth that
    follows the normals between seen neighbours: the surface continued across a region the
    images say nothing about.

    The depth z over the mask minimises :func:`integrate_normals`' equations (n̄_z Δz = −n̄_x along
    +col, n̄_z Δz = n̄_y along +row) for pairs of seen pixels, plus ``smoothness``² Σ (second
    difference of z)² centred on unseen pixels and their neighbours. With ``outline``, the
    unseen pixels on the object's outline also give the same equations for the normal the seen
    outline gives them (:func:`outline_normals`): a surface continued up to the outline turns
    away from the camera there as the rest of the outline does, where the least-curved depth
    alone would run on flat. The unseen pixels' normals are (−∂z/∂x, −∂z/∂y, 1) normalised,
    from central differences where both neighbours are on the object and one-sided ones
    elsewhere (+y is −row).

    Args:
        normals: (H, W, 3) unit normals.
        mask: (H, W) bool; unseen: (H, W) bool, inside the mask.

    Returns:
        (H, W, 3) float32; equal to ``normals`` outside ``unseen``.
    """
    out = normals.astype(np.float32, copy=True)
    if not unseen.any():
        return out
    h, w = mask.shape
    index = -np.ones((h, w), np.int64)
    index[mask] = np.arange(mask.sum())
    rows, cols, values, rhs = [], [], [], []

    def add(columns: list[np.ndarray], weights: list, target: np.ndarray) -> None:
        first = sum(len(r) for r in rhs)
        equation = np.arange(first, first + target.size)
        for column, weight in zip(columns, weights):
            rows.append(equation)
            cols.append(column)
            values.append(np.broadcast_to(weight, (target.size,)))
        rhs.append(target)

    first, second, nz, target = orientation_equations(normals, index, mask & ~unseen)
    add([second, first], [nz, -nz], target)
    near = binary_dilation(unseen, np.ones((3, 3), bool))
    for dr, dc in ((0, 1), (1, 0)):
        a, centre = index[: h - 2 * dr, : w - 2 * dc], index[dr: h - dr, dc: w - dc]
        b = index[2 * dr:, 2 * dc:]
        ok = (a >= 0) & (centre >= 0) & (b >= 0) & near[dr: h - dr, dc: w - dc]
        add([a[ok], centre[ok], b[ok]], [smoothness, -2 * smoothness, smoothness], np.zeros(int(ok.sum())))
    anchored = outline_normals(normals, mask, unseen) if outline else None
    if anchored is not None:
        anchors, target = anchored
        for (dr, dc), component, sign in (((0, 1), 0, -1.0), ((1, 0), 1, 1.0)):
            a, b = index[: h - dr, : w - dc], index[dr:, dc:]
            first_anchored = anchors[: h - dr, : w - dc]
            ok = (a >= 0) & (b >= 0) & (first_anchored | anchors[dr:, dc:])
            pair = np.where(first_anchored[..., None], target[: h - dr, : w - dc], target[dr:, dc:])[ok]
            add([b[ok], a[ok]], [pair[:, 2], -pair[:, 2]], sign * pair[:, component])
    m = int(mask.sum())
    system = sp.csr_matrix((np.concatenate(values), (np.concatenate(rows), np.concatenate(cols))),
                           shape=(sum(len(r) for r in rhs), m))
    z = spsolve((system.T @ system + 1e-8 * sp.eye(m)).tocsc(), system.T @ np.concatenate(rhs))
    depth = np.zeros((h + 2, w + 2))              # a border off the object: no wrap-around
    on = np.pad(mask, 1)
    depth[on] = z
    slopes = []
    for axis in (1, 0):
        ahead, behind = np.roll(depth, -1, axis), np.roll(depth, 1, axis)
        on_ahead, on_behind = np.roll(on, -1, axis), np.roll(on, 1, axis)
        slope = np.where(on_ahead & on_behind, (ahead - behind) / 2,
                         np.where(on_ahead, ahead - depth, np.where(on_behind, depth - behind, 0)))
        slopes.append(slope[1:-1, 1:-1])
    continued = np.stack([-slopes[0], slopes[1], np.ones((h, w))], -1)
    continued /= np.linalg.norm(continued, axis=-1, keepdims=True)
    out[unseen] = continued[unseen]
    return out


OUTLINE_SEEN_SHARE = 0.1
"""The share of the outline that must be seen for :func:`outline_normals` to read it."""
OUTLINE_AGREEMENT = 0.75
"""The share of the seen outline whose normals must lean the same way across it (outward, as a
solid's, or inward, as a shell's seen from inside) for :func:`outline_normals` to continue it."""


def outline_normals(normals: np.ndarray, mask: np.ndarray, unseen: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray] | None:
    """The unseen part of an object's outline, and the normal each of its pixels is given: the
    seen outline's, in the outline's own frame.

    On the outline of a solid seen whole the surface turns away from the camera (the occluding
    contour): its normal leans outward across the outline (:func:`outward_directions`), tilted
    toward the camera only as far as a pixel's centre lies inside the outline. A shell seen from
    inside leans inward there, a rim can face the camera. The seen outline pixels say which and
    how far: each unseen one gets their median lean across the outline (n·outward) and their
    median n_z, along its own outward direction. Where the seen outline does not lean one way
    (less than :data:`OUTLINE_AGREEMENT` of it on the median's side, as on a plane tilted away
    from the camera), too little of it is seen, or its median normal faces away from the camera
    (n_z ≤ 0: no surface the camera sees does; the fit there is noise), nothing is given. The
    outline is the object's pixels with a neighbour (of eight) off the object inside the frame:
    an object cut by the frame's edge has no outline there.

    Args:
        normals: (H, W, 3) unit normals; mask, unseen: (H, W) bool, ``unseen`` inside ``mask``.

    Returns:
        (H, W) bool, the unseen outline pixels, and (H, W, 3) unit normals (valid there); None
        where no unseen pixel is on the outline, less than :data:`OUTLINE_SEEN_SHARE` of the
        outline is seen, the seen part does not agree or faces away.

    >>> r, c = np.mgrid[-6:7, -6:7]
    >>> disc = np.hypot(r, c) <= 5.5
    >>> sphere = np.stack([c, -r, np.sqrt(np.clip(36 - r ** 2 - c ** 2, 0, None))], -1) / 6
    >>> anchors, target = outline_normals(sphere, disc, disc & (c < -3))    # its left side unseen
    >>> int(anchors.sum()), (np.round(target[6, 0], 2) + 0).tolist()        # the leftmost pixel faces left
    (9, [-0.83, 0.0, 0.56])
    """
    edge = mask & ~binary_erosion(mask, np.ones((3, 3), bool), border_value=1)
    seen = edge & ~unseen
    anchors = edge & unseen
    if not anchors.any() or seen.sum() < OUTLINE_SEEN_SHARE * edge.sum():
        return None
    outward = outward_directions(mask)
    lean = (normals[..., :2] * outward).sum(-1)[seen]
    across = float(np.median(lean))
    if np.mean(np.sign(lean) == np.sign(across)) < OUTLINE_AGREEMENT:
        return None
    nz = float(np.median(normals[seen][:, 2]))
    if nz <= 0:              # facing away from the camera: what the fit has there is noise
        return None
    target = np.concatenate([across * outward, np.full(mask.shape + (1,), nz)], -1)
    return anchors, target / np.maximum(np.linalg.norm(target, axis=-1, keepdims=True), 1e-12)


OUTWARD_SMOOTHING = 2.0
"""σ in pixels of the Gaussian over the signed distance in :func:`outward_directions`."""


def outline_distance(mask: np.ndarray) -> np.ndarray:
    """(H, W) each object pixel's distance to the nearest pixel off the object, the image's frame
    counting as off it (1 on the outline, 0 off the object).

    >>> outline_distance(np.pad(np.ones((3, 3), bool), 1))[1:4, 1:4].tolist()
    [[1.0, 1.0, 1.0], [1.0, 2.0, 1.0], [1.0, 1.0, 1.0]]
    >>> outline_distance(np.ones((1, 3), bool)).tolist()        # on the frame's edge
    [[1.0, 1.0, 1.0]]
    """
    return distance_transform_edt(np.pad(mask, 1))[1:-1, 1:-1]


def outward_directions(mask: np.ndarray) -> np.ndarray:
    """(H, W, 2) unit (x, y) directions out of the object, across its outline: the negated
    gradient of the signed distance to the outline, smoothed over two pixels (σ) so that a
    staircase outline reads as the curve it samples (on a pixelated disc of radius 8–40, within
    1° of the radial direction on average and 3.4° at most, against 3° and 8° smoothed over one).

    >>> square = np.zeros((7, 7), bool); square[1:6, 1:6] = True
    >>> outward = np.round(outward_directions(square), 3) + 0
    >>> outward[3, 1].tolist(), outward[1, 3].tolist()         # the left side, the top
    ([-1.0, 0.0], [0.0, 1.0])
    """
    signed = distance_transform_edt(mask) - distance_transform_edt(~mask)
    d_row, d_col = np.gradient(gaussian_filter(signed.astype(np.float64), OUTWARD_SMOOTHING))
    outward = np.stack([-d_col, d_row], -1)                         # x = +col, y = −row
    return outward / np.maximum(np.linalg.norm(outward, axis=-1, keepdims=True), 1e-12)


def depth_to_mesh(depth: np.ndarray, mask: np.ndarray, frame: Frame | None = None
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Triangulate a depth map over the mask.

    Every 2×2 block of object pixels gives two triangles, a block with three gives one;
    triangles wind counter-clockwise seen from the camera, so their normals face +z.

    Args:
        depth: (H, W) depth in pixel units.
        mask: (H, W) bool.
        frame: if given, vertices are placed in the source image's pixel coordinates
            (x = col, y = −row, z scaled by the downsampling step), so meshes of crops and
            downsampled runs line up with full-resolution ones.

    Returns:
        vertices (V, 3) float32 in the unps frame, faces (F, 3) int32 indices.
    """
    h, w = mask.shape
    index = -np.ones((h, w), dtype=np.int64)
    index[mask] = np.arange(mask.sum())
    r, c = np.nonzero(mask)
    z = depth[mask].astype(np.float64)
    if frame is not None:
        r, c = frame.source_coords(r, c)
        z = z * frame.step
    vertices = np.stack([c, -r, z], axis=1).astype(np.float32)
    # Corners of each block in counter-clockwise order seen from +z: (0,0) (1,0) (1,1) (0,1).
    corners = np.stack([index[:-1, :-1], index[1:, :-1], index[1:, 1:], index[:-1, 1:]], -1)
    corners = corners.reshape(-1, 4)
    present = corners >= 0
    full = corners[present.all(1)]
    faces = [full[:, [0, 1, 2]], full[:, [0, 2, 3]]]
    three = corners[present.sum(1) == 3]
    if len(three):
        keep = three >= 0
        faces.append(three[keep].reshape(-1, 3))   # the three present corners, still in cyclic order
    return vertices, np.concatenate(faces).astype(np.int32)


def cast_shadows(depth: torch.Tensor, mask: torch.Tensor, lights: torch.Tensor, pitch: float,
                 steps: int, chunk: int = 16) -> torch.Tensor:
    """Which object pixels each light cannot see, marching the depth map toward the light.

    From each object pixel, ``steps`` samples spaced evenly over the image's diagonal are taken
    along the light's image-plane direction (nearest pixel); the ray rises by l_z / |l_xy| per
    unit of distance, and the pixel is in shadow if the object stands above it at any sample.
    Samples beyond the distance at which a light's ray has risen past the object's whole depth
    range cannot be in shadow and are not taken (steep lights need a few of them).

    Args:
        depth: (H, W) float32 depth along +z, in units of which one pixel is ``pitch``.
        mask: (H, W) bool object mask, on ``depth``'s device.
        lights: (n, 3) unit directions, surface to light, on ``depth``'s device.
        pitch: one pixel's size in depth units (1 when depth is in pixels).
        steps: samples along each ray.
        chunk: lights marched at once (memory grows as chunk × steps × object pixels).

    Returns:
        (n, H, W) bool, on ``depth``'s device.
    """
    h, w = depth.shape
    out = torch.zeros(len(lights), h, w, dtype=torch.bool, device=depth.device)
    rows, cols = torch.nonzero(mask, as_tuple=True)
    if not len(rows):
        return out
    distance = march_distances(h, w, steps, depth.device)
    border = int(distance[-1]) + 2                  # off the image: a frame of −∞ around it
    surface = F.pad(torch.where(mask, depth, -torch.inf), (border,) * 4, value=-torch.inf)
    surface, width = surface.flatten(), w + 2 * border
    start = depth[rows, cols]
    span = float(start.max() - start.min())
    planar = lights[:, :2].norm(dim=-1).clamp_min(1e-6)
    rise = lights[:, 2] / planar                                              # per unit of distance
    reach = torch.where(rise > 0, span / (pitch * rise.clamp_min(1e-12)), torch.inf)   # in pixels
    order = torch.argsort(reach)                          # lights of like reach marched together
    for first in range(0, len(lights), chunk):
        index = order[first:first + chunk]
        taken = distance[distance <= reach[index].max()]
        if not len(taken):
            continue
        step = torch.stack([-lights[index, 1], lights[index, 0]], -1) / planar[index, None]
        out[index[:, None], rows[None], cols[None]] = occluded(surface, width, border, rows, cols, start,
                                                               taken, pitch, step, rise[index])
    return out


def march_distances(h: int, w: int, steps: int, device: torch.device) -> torch.Tensor:
    """(steps,) distances in pixels at which a shadow ray samples the depth: 1 to the diagonal."""
    return torch.linspace(1, (h ** 2 + w ** 2) ** 0.5, steps, device=device)


def occluded(surface: torch.Tensor, width: int, border: int, rows: torch.Tensor, cols: torch.Tensor,
             start: torch.Tensor, taken: torch.Tensor, pitch: float, step: torch.Tensor,
             rise: torch.Tensor, base: torch.Tensor | int = 0) -> torch.Tensor:
    """Whether the surface stands above a ray at any of its samples: the pixel at sample distance
    d along a light's image-plane direction (nearest pixel), against the ray's height there.

    Args:
        surface: the padded depth, flattened, −∞ off the object (several images end to end).
        width, border: the padded image's row length and the frame added around it.
        rows, cols: (P,) the rays' pixels; start: (P,) or (C, P) their depth.
        taken: (T,) sample distances in pixels; pitch: one pixel in depth units.
        step: (C, 2) (row, col) per pixel of distance toward each of C lights; rise: (C,) the
            rays' rise per unit of distance.
        base: 0, or (C, 1, 1) where each light's padded image starts in ``surface``.

    Returns:
        (C, P) bool.
    """
    r = (rows[..., None, :] + taken[None, :, None] * step[:, 0, None, None]).round().int()
    c = (cols[..., None, :] + taken[None, :, None] * step[:, 1, None, None]).round().int()
    ray = start[..., None, :] + (taken * pitch)[None, :, None] * rise[:, None, None]
    return (surface[base + (r + border) * width + c + border] > ray + 1e-3).any(1)


@dataclass(frozen=True)
class ShadowPlan:
    """Everything that decides a batch of shadow marches, computed on the CPU so that a GPU
    marching them is never waited on: B depth maps under n lights each, the B·n (image, light)
    pairs in order of reach.

    Attributes:
        depth: (B, H, W) float32; mask: (B, H, W) bool.
        order: (B·n,) the pairs (image · n + light), shortest reach first.
        samples: (B·n,) in that order, how many of the ray samples each pair needs.
        step: (B·n, 2) (row, col) per pixel of distance toward each pair's light; rise: (B·n,)
            its ray's rise per unit of distance.
        distance: (steps,) the sample distances in pixels; border: the −∞ frame padded around
            each image; pitch: one pixel in depth units.
    """

    depth: torch.Tensor
    mask: torch.Tensor
    order: torch.Tensor
    samples: torch.Tensor
    step: torch.Tensor
    rise: torch.Tensor
    distance: torch.Tensor
    border: int
    pitch: float


def plan_shadows(depth: torch.Tensor, mask: torch.Tensor, lights: torch.Tensor, pitch: float,
                 steps: int) -> ShadowPlan:
    """The :class:`ShadowPlan` of (B, H, W) depth maps and masks under (B, n, 3) lights, all on
    the CPU (as :func:`cast_shadows` decides it for each image: samples beyond a ray's reach
    cannot be in shadow; an empty mask casts nothing)."""
    h, w = depth.shape[1:]
    n = lights.shape[1]
    distance = march_distances(h, w, steps, torch.device("cpu"))
    span = torch.stack([(d[m].max() - d[m].min()) if m.any() else torch.tensor(0.0)
                        for d, m in zip(depth, mask)])
    planar = lights[..., :2].norm(dim=-1).clamp_min(1e-6)
    rise = lights[..., 2] / planar
    reach = torch.where(rise > 0, span[:, None] / (pitch * rise.clamp_min(1e-12)), torch.inf).flatten()
    reach[~mask.flatten(1).any(1).repeat_interleave(n)] = 0.0
    order = torch.argsort(reach)
    step = torch.stack([-lights[..., 1], lights[..., 0]], -1).flatten(0, 1) / planar.flatten()[:, None]
    return ShadowPlan(depth, mask, order, torch.searchsorted(distance, reach[order], right=True), step,
                      rise.flatten(), distance, int(distance[-1]) + 2, pitch)


MARCH_BUDGET = {"cpu": 2 ** 24, "cuda": 2 ** 26}
"""Ray samples (pairs × samples × pixels) :func:`march_shadows` takes at once, by device type: on
a GPU each chunk is a dozen kernels whose launches, not their work, set the time, so it takes
larger ones (about 1.5 GB of temporaries)."""


def march_shadows(plan: ShadowPlan, device: torch.device, budget: int | None = None) -> torch.Tensor:
    """(B, n, H, W) bool on ``device``: :func:`cast_shadows` of each of the plan's images, all
    marched as one queue of kernels, at most ``budget`` samples (pairs × samples × pixels) at a
    time (None: :data:`MARCH_BUDGET` of the device's type, that of ``cuda`` for any other)."""
    b, h, w = plan.depth.shape
    pairs, border = len(plan.order), plan.border
    budget = budget or MARCH_BUDGET.get(device.type, MARCH_BUDGET["cuda"])
    to = lambda x: x.to(device, non_blocking=True)     # noqa: E731
    depth, mask = to(plan.depth), to(plan.mask)
    surface = F.pad(torch.where(mask, depth, -torch.inf), (border,) * 4, value=-torch.inf)
    padded = surface.shape[1] * surface.shape[2]
    surface, start = surface.flatten(), depth.flatten(1)
    order, step, rise, distance = to(plan.order), to(plan.step), to(plan.rise), to(plan.distance)
    rows, cols = (g.flatten().float() for g in torch.meshgrid(
        torch.arange(h, device=device), torch.arange(w, device=device), indexing="ij"))
    out = torch.zeros(pairs, h * w, dtype=torch.bool, device=device)
    samples = plan.samples.tolist()
    for first, end in march_chunks(samples, h * w, budget):
        count = samples[end - 1]                       # the chunk's longest reach
        index = order[first:end]
        image = index // (pairs // b)
        out[index] = occluded(surface, w + 2 * border, border, rows, cols, start[image], distance[:count],
                              plan.pitch, step[index], rise[index], (image * padded)[:, None, None])
    return out.view(b, pairs // b, h, w) & mask[:, None]


def march_chunks(samples: list[int], pixels: int, budget: int) -> list[tuple[int, int]]:
    """The pairs marched together: [first, end) ranges of the plan's order, each as long as its
    pairs × its longest reach × ``pixels`` stays within ``budget`` (one pair at least); pairs
    that need no sample are left out.

    Args:
        samples: each pair's samples, in the plan's order (non-decreasing).

    Example:
        >>> march_chunks([0, 0, 1, 2, 2, 5], pixels=1, budget=4)
        [(2, 4), (4, 5), (5, 6)]
    """
    chunks, first = [], next((i for i, count in enumerate(samples) if count), len(samples))
    while first < len(samples):
        end = first + 1
        while end < len(samples) and (end + 1 - first) * samples[end] * pixels <= budget:
            end += 1
        chunks.append((first, end))
        first = end
    return chunks

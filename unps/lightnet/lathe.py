"""Jars, vases and cups seen at any tilt: open surfaces of revolution, rasterised by z-buffer.

A height field cannot hold a vase tilted toward the camera (the near lip hides part of the
cavity, the far inner wall stands up behind it), so these shapes are sampled densely as points
with their exact normals and the nearest point per pixel is kept.

Frame: x right, y up, z toward the camera; the orthographic view covers [−1, 1]² (row 0 at
y = 1), depth in the same units.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import torch
import torch.nn.functional as F


@dataclass(frozen=True)
class Part:
    """A grid of a jar's points, (k, s): k along its profile, s around the axis.

    Attributes:
        x, y, z: (k, s) the points; slope: (k,) dr/dz of a wall, None for a flat annulus;
        side: a wall's normals point outward for 1 and inward for −1; an annulus's are (0, 0, side).
    """

    x: torch.Tensor
    y: torch.Tensor
    z: torch.Tensor
    slope: torch.Tensor | None
    side: float

    def normals(self, ring: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
        """(q, 3) unit normals of the points at flat ``index`` (q,) into this part's grid."""
        if self.slope is None:
            return torch.tensor([0.0, 0.0, self.side]).expand(len(index), 3)
        along, around = index // ring.shape[0], index % ring.shape[0]
        raw = torch.cat([ring[around], -self.slope[along, None]], -1)
        return self.side * F.normalize(raw, dim=-1)


@dataclass(frozen=True)
class Jar:
    """An open jar as points, in parts, with their normals worked out on demand (a view of it
    needs only the normals of the points it shows). Point i is the i-th of the parts' grids
    flattened one after the other."""

    parts: tuple[Part, ...]
    ring: torch.Tensor    # (s, 2) cos, sin of the angles around the axis

    def coordinates(self) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(p,) x, (p,) y and (p,) z of every point."""
        return tuple(torch.cat([getattr(part, axis).flatten() for part in self.parts]) for axis in "xyz")

    @property
    def points(self) -> torch.Tensor:
        """(p, 3) every point."""
        return torch.stack(self.coordinates(), -1)

    def normals(self, index: torch.Tensor | None = None) -> torch.Tensor:
        """(q, 3) unit normals of the points at ``index`` (q,) (every point for None): outward
        on the outside, into the cavity on the inside."""
        sizes = [part.x.numel() for part in self.parts]
        if index is None:
            index = torch.arange(sum(sizes))
        normals = torch.empty(len(index), 3)
        start = 0
        for part, size in zip(self.parts, sizes):
            inside = (index >= start) & (index < start + size)
            normals[inside] = part.normals(self.ring, index[inside] - start)
            start += size
        return normals


def jar_points(radius, height: float, floor: float, wall: float, samples: int) -> Jar:
    """An open jar standing on z = 0 with its axis along +z, sampled as points.

    Args:
        radius: callable (k,) heights in [0, 1] → (k,) outer radii.
        height: the jar's height.
        floor: height of the inside floor, as a share of ``height``.
        wall: wall thickness; 0 gives one sheet with no lip and no separate inside floor (its
            inside is the back of its outside: rasterise it ``two_sided``).
        samples: points around the axis; the other directions are sampled in proportion.
    """
    theta = torch.linspace(0, 2 * math.pi, samples + 1)[:-1]
    ring = torch.stack([torch.cos(theta), torch.sin(theta)], -1)             # (s, 2)
    h = torch.linspace(0, 1, samples)
    outer = radius(h)
    slope = torch.gradient(outer, spacing=1 / (samples - 1))[0] / height     # dr/dz
    base = torch.linspace(0, 1, samples // 4)[:, None]
    if wall == 0:
        return Jar((_wall(ring, outer, h * height, slope, 1.0),
                    _disc(ring, base * outer[0], 0.0, -1.0)), ring)
    inner = (outer - wall).clamp_min(0.02)
    inside = h >= floor
    return Jar((
        _wall(ring, outer, h * height, slope, 1.0),
        _wall(ring, inner[inside], h[inside] * height, slope[inside], -1.0),
        _disc(ring, base * outer[0], 0.0, -1.0),
        _disc(ring, base * inner[inside][0], float(h[inside][0]) * height, 1.0),
        _disc(ring, inner[-1] + base * (outer[-1] - inner[-1]), height, 1.0),
    ), ring)


def jar_view(radius, height: float, floor: float, wall: float, tilt: float, turn: float,
             extent: float, resolution: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """A jar of :func:`jar_points` seen tilted and turned, centred, rasterised.

    Args:
        radius, height, floor, wall: as :func:`jar_points` (``wall`` 0: one sheet, shown
            two-sided).
        tilt: radians away from looking into the mouth (about x; 0: into the mouth).
        turn: radians about the view axis, after the tilt.
        extent: the jar's longer side in the image, in view units (the view is 2 wide).
        resolution: image side in pixels.

    Returns:
        normals (R, R, 3), depth (R, R) and mask (R, R), as :func:`rasterise`.
    """
    jar = jar_points(radius, height, floor, wall, samples=4 * resolution)
    c, s, ct, st = math.cos(tilt), math.sin(tilt), math.cos(turn), math.sin(turn)
    rotation = torch.tensor([[ct, -st, 0], [st, ct, 0], [0, 0, 1.0]]) @ torch.tensor(
        [[1.0, 0, 0], [0, c, -s], [0, s, c]])
    coordinates = jar.coordinates()
    x, y, z = (_rotated(coordinates, row) for row in rotation)
    low = torch.stack([x.min(), y.min(), z.min()])
    high = torch.stack([x.max(), y.max(), z.max()])
    centre, scale = (low + high) / 2, extent / float((high - low)[:2].max())

    def normals(index: torch.Tensor) -> torch.Tensor:
        shown = jar.normals(index).unbind(-1)
        return torch.stack([_rotated(shown, row) for row in rotation], -1)

    return rasterise(*((v - centre[i]) * scale for i, v in enumerate((x, y, z))), normals, resolution,
                     two_sided=wall == 0)


def _rotated(vectors: tuple[torch.Tensor, ...], row: torch.Tensor) -> torch.Tensor:
    """(p,) one coordinate of vectors given as their (p,) x, y, z, turned by a rotation whose
    row is ``row`` (3,): the products summed in order, the same bits on every CPU (a (p, 3) × (3, 3)
    matmul may fuse them, as an Intel Xeon's kernels do)."""
    x, y, z = vectors
    return x * row[0] + y * row[1] + z * row[2]


def _wall(ring, r, z, slope, side: float) -> Part:
    """A wall of revolution: radii r (k,) at heights z (k,), normals outward for side 1, inward for
    −1."""
    return Part(r[:, None] * ring[:, 0], r[:, None] * ring[:, 1], z[:, None].expand(-1, len(ring)),
                slope, side)


def _disc(ring, r, z: float, up: float) -> Part:
    """A flat annulus of radii r (k, 1) at height z, normals (0, 0, up)."""
    return Part(r * ring[:, 0], r * ring[:, 1], torch.full((len(r), len(ring)), z), None, up)


def rasterise(x: torch.Tensor, y: torch.Tensor, z: torch.Tensor,
              normals: torch.Tensor | Callable[[torch.Tensor], torch.Tensor], resolution: int,
              two_sided: bool = False) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Nearest visible point per pixel, orthographic along −z.

    Args:
        x, y, z: (p,) the points in view units, x and y within [−1, 1].
        normals: (p, 3) their unit normals, or a function giving the (q, 3) normals of the
            points at (q,) indices: it is asked only for the points that show.
        resolution: R, the image side in pixels (below 4096).
        two_sided: the points sample a sheet with no thickness, which shows the camera
            whichever of its sides faces it: each normal is turned toward the camera.

    Returns:
        normals (R, R, 3) unit, depth (R, R) and mask (R, R) bool: pixels whose nearest point
        faces the camera (of points tied for nearest, the last), with no empty pixel inside the
        mask (the few that no point hit are filled from their neighbours).
    """
    col = ((x + 1) / 2 * (resolution - 1)).round().clamp(0, resolution - 1)
    row = ((1 - y) / 2 * (resolution - 1)).round().clamp(0, resolution - 1)
    pixel = (row * resolution + col).long()          # whole numbers below 2^24: exact in float32
    depth = torch.full((resolution * resolution,), -torch.inf).scatter_reduce(0, pixel, z, "amax")
    front = torch.nonzero(z >= depth[pixel]).squeeze(1)
    # of the points tied for nearest, the last: a plain indexed write would leave it to the threads
    last = torch.full((resolution * resolution,), -1).scatter_reduce(0, pixel[front], front, "amax")
    hit = last >= 0
    shown = normals[last[hit]] if isinstance(normals, torch.Tensor) else normals(last[hit])
    if two_sided:
        shown = shown * torch.where(shown[:, 2:] < 0, -1.0, 1.0)
    normal = torch.zeros(resolution * resolution, 3)
    normal[hit] = shown
    return _maps(depth, normal, resolution)


def _maps(depth: torch.Tensor, normal: torch.Tensor, resolution: int
          ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """:func:`rasterise`'s maps from a z-buffer, (R·R,) ``depth`` and (R·R, 3) ``normal``: the
    pixels no point hit inside the outline filled from their neighbours, the mask those facing
    the camera."""
    depth, normal = depth.view(resolution, resolution), normal.view(resolution, resolution, 3)
    hit = torch.isfinite(depth)
    holes = _filled(hit) & ~hit
    if holes.any():
        grown = -F.max_pool2d(-torch.where(hit, depth, torch.inf)[None, None], 3, 1, 1)[0, 0]
        grown_normal = F.avg_pool2d((normal * hit[..., None]).permute(2, 0, 1)[None], 3, 1, 1)[0]
        depth = torch.where(holes, grown, depth)   # the farther neighbour: a hole is never in front
        normal = torch.where(holes[..., None], F.normalize(grown_normal.permute(1, 2, 0), dim=-1), normal)
    mask = _filled(hit) & (normal[..., 2] > 0.02)
    return normal * mask[..., None], torch.where(mask, depth, torch.zeros_like(depth)), mask


def _filled(hit: torch.Tensor) -> torch.Tensor:
    """The mask closed by one pixel: single empty pixels between hit ones count as inside."""
    grown = F.max_pool2d(hit[None, None].float(), 3, 1, 1)
    return (-F.max_pool2d(-grown, 3, 1, 1))[0, 0] > 0.5

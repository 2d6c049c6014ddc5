"""Jars, vases and cups seen at any tilt: open surfaces of revolution, rasterised by z-buffer.

A height field cannot hold a vase tilted toward the camera (the near lip hides part of the
cavity, the far inner wall stands up behind it), so these shapes are sampled densely as points
with their exact normals and the nearest point per pixel is kept.

Frame: x right, y up, z toward the camera; the orthographic view covers [−1, 1]² (row 0 at
y = 1), depth in the same units.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F


def profile_points(radius, height: float, floor: float, wall: float, samples: int
                   ) -> tuple[torch.Tensor, torch.Tensor]:
    """Points and unit normals of an open jar standing on z = 0 with its axis along +z.

    Args:
        radius: callable (k,) heights in [0, 1] → (k,) outer radii.
        height: the jar's height.
        floor: height of the inside floor, as a share of ``height``.
        wall: wall thickness; 0 gives one sheet with no lip and no separate inside floor (its
            inside is the back of its outside: rasterise it ``two_sided``).
        samples: points around the axis; the other directions are sampled in proportion.

    Returns:
        (p, 3) points and (p, 3) outward-facing unit normals (into the cavity on the inside).
    """
    theta = torch.linspace(0, 2 * math.pi, samples + 1)[:-1]
    ring = torch.stack([torch.cos(theta), torch.sin(theta)], -1)             # (s, 2)
    h = torch.linspace(0, 1, samples)
    outer = radius(h)
    slope = torch.gradient(outer, spacing=1 / (samples - 1))[0] / height     # dr/dz
    base = torch.linspace(0, 1, samples // 4)[:, None]
    if wall == 0:
        sheet = [_wall(ring, outer, h * height, slope, 1.0), _disc(ring, base * outer[0], 0.0, -1.0)]
        return torch.cat([p for p, _ in sheet]), torch.cat([n for _, n in sheet])
    inner = (outer - wall).clamp_min(0.02)
    inside = h >= floor
    parts = [                                                                 # (points, normals)
        _wall(ring, outer, h * height, slope, 1.0),
        _wall(ring, inner[inside], h[inside] * height, slope[inside], -1.0),
        _disc(ring, base * outer[0], 0.0, -1.0),
        _disc(ring, base * inner[inside][0], float(h[inside][0]) * height, 1.0),
        _disc(ring, inner[-1] + base * (outer[-1] - inner[-1]), height, 1.0),
    ]
    return torch.cat([p for p, _ in parts]), torch.cat([n for _, n in parts])


def jar_view(radius, height: float, floor: float, wall: float, tilt: float, turn: float,
             extent: float, resolution: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """A jar of :func:`profile_points` seen tilted and turned, centred, rasterised.

    Args:
        radius, height, floor, wall: as :func:`profile_points` (``wall`` 0: one sheet, shown
            two-sided).
        tilt: radians away from looking into the mouth (about x; 0: into the mouth).
        turn: radians about the view axis, after the tilt.
        extent: the jar's longer side in the image, in view units (the view is 2 wide).
        resolution: image side in pixels.

    Returns:
        normals (R, R, 3), depth (R, R) and mask (R, R), as :func:`rasterise`.
    """
    points, normals = profile_points(radius, height, floor, wall, samples=4 * resolution)
    c, s, ct, st = math.cos(tilt), math.sin(tilt), math.cos(turn), math.sin(turn)
    rotation = torch.tensor([[ct, -st, 0], [st, ct, 0], [0, 0, 1.0]]) @ torch.tensor(
        [[1.0, 0, 0], [0, c, -s], [0, s, c]])
    points, normals = points @ rotation.T, normals @ rotation.T
    low, high = points.min(0).values, points.max(0).values
    points = (points - (low + high) / 2) * (extent / float((high - low)[:2].max()))
    return rasterise(points, normals, resolution, two_sided=wall == 0)


def _wall(ring, r, z, slope, side: float):
    """Points of a wall of revolution and its normals (outward for side 1, inward for −1)."""
    points = torch.cat([r[:, None, None] * ring, z[:, None, None].expand(-1, len(ring), 1)], -1)
    normals = torch.cat([ring.expand(len(r), -1, -1), -slope[:, None, None].expand(-1, len(ring), 1)], -1)
    return points.reshape(-1, 3), side * F.normalize(normals.reshape(-1, 3), dim=-1)


def _disc(ring, r, z: float, up: float):
    """Points of a flat annulus (radii r: (k, 1)) at height z, normals ±z."""
    points = torch.cat([(r[..., None] * ring).reshape(-1, 2), torch.full((r.numel() * len(ring), 1), z)], -1)
    return points, torch.tensor([0.0, 0.0, up]).expand_as(points)


def rasterise(points: torch.Tensor, normals: torch.Tensor, resolution: int,
              two_sided: bool = False) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Nearest visible point per pixel, orthographic along −z.

    Args:
        points, normals: (p, 3) in view units, x and y within [−1, 1].
        two_sided: the points sample a sheet with no thickness, which shows the camera
            whichever of its sides faces it: each normal is turned toward the camera.

    Returns:
        normals (R, R, 3) unit, depth (R, R) and mask (R, R) bool: pixels whose nearest point
        faces the camera, with no empty pixel inside the mask (the few that no point hit are
        filled from their neighbours).
    """
    if two_sided:
        normals = normals * torch.where(normals[:, 2:] < 0, -1.0, 1.0)
    col = ((points[:, 0] + 1) / 2 * (resolution - 1)).round().long().clamp(0, resolution - 1)
    row = ((1 - points[:, 1]) / 2 * (resolution - 1)).round().long().clamp(0, resolution - 1)
    pixel = row * resolution + col
    depth = torch.full((resolution * resolution,), -torch.inf).scatter_reduce(
        0, pixel, points[:, 2], "amax")
    front = torch.nonzero(points[:, 2] >= depth[pixel]).squeeze(1)
    # of the points tied for nearest, the last: a plain indexed write would leave it to the threads
    last = torch.full((resolution * resolution,), -1).scatter_reduce(0, pixel[front], front, "amax")
    normal = torch.zeros(resolution * resolution, 3)
    normal[last >= 0] = normals[last[last >= 0]]
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

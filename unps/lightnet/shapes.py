"""Scenes for the light network's training data: shapes as normal and depth maps, in seven
families (:data:`SHAPES`; meshes: :mod:`unps.lightnet.meshes`), and the shadows they cast.

Frame: x right, y up, z toward the camera; the orthographic view covers [−1, 1]², so one
pixel is 2 / resolution units and depth is in the same units.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass

import torch
import torch.nn.functional as F

from unps import geometry
from unps.errors import InputError
from unps.lightnet import lathe


@dataclass(frozen=True)
class ShapeMaps:
    """normals (H, W, 3) unit, depth (H, W), mask (H, W) bool; float32 tensors."""

    normals: torch.Tensor
    depth: torch.Tensor
    mask: torch.Tensor

    def to(self, device: torch.device) -> ShapeMaps:
        """The same maps on ``device``."""
        return ShapeMaps(self.normals.to(device), self.depth.to(device), self.mask.to(device))


def sample_generator(seed: int, index: int) -> torch.Generator:
    digest = hashlib.sha256(f"{seed}:{index}".encode()).digest()
    return torch.Generator().manual_seed(int.from_bytes(digest[:8], "little"))


def blob(resolution: int, generator: torch.Generator) -> ShapeMaps:
    """A smooth random blob: a dome over a star-shaped outline, with Gaussian bumps and dents."""
    u = lambda *shape: torch.rand(*shape, generator=generator)    # noqa: E731
    x, y, phi, rho = _plane(resolution)
    outline = _star_outline(phi, generator)
    r = (rho / outline).clamp(max=1)
    height = (0.4 + 0.6 * u(1)) * outline.mean()
    z = height * torch.sqrt(1 - r ** 2)        # smooth at the centre, whatever the outline
    for _ in range(int(3 + 8 * u(1))):
        cx, cy = (u(2) - 0.5) * 1.2
        width = 0.08 + 0.3 * u(1)
        amplitude = (u(1) - 0.4) * 0.6 * width
        z = z + amplitude * torch.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * width ** 2)) * (r < 1)
    mask = rho < 0.985 * outline
    return maps_from_depth(z, mask)


def dish(resolution: int, generator: torch.Generator) -> ShapeMaps:
    """A dish, shard or cupped petal seen from inside: a concave cap, curved less along one axis
    (down to a trough), over a star-shaped outline, tilted up to 35°, with bumps and dents. Its
    outline is a rim, not an occluding contour: it shades as a dome does under the lights mirrored
    through the view axis, and only the shadows its rim casts and the light its inside bounces
    tell the two apart."""
    u = lambda *shape: torch.rand(*shape, generator=generator)    # noqa: E731
    x, y, phi, rho = _plane(resolution)
    outline = _star_outline(phi, generator)
    rim_slope = math.radians(20 + 55 * float(u(1)))        # the wall's slope at the farthest rim
    sphere = float(outline.max()) / math.sin(rim_slope)
    across, along = _turned(x, y, 2 * math.pi * float(u(1)))
    flatter = 0.3 + 0.7 * float(u(1))                      # 0.3: nearly a trough, as a pot's shard
    z = -torch.sqrt((sphere ** 2 - across ** 2 - (flatter * along) ** 2).clamp_min(0))
    for _ in range(int(2 + 6 * u(1))):
        cx, cy = (u(2) - 0.5) * 1.2
        width = 0.08 + 0.3 * u(1)
        amplitude = (u(1) - 0.5) * 0.4 * width
        z = z + amplitude * torch.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * width ** 2))
    tilt, turn = math.tan(math.radians(35) * float(u(1))), 2 * math.pi * float(u(1))
    z = z + tilt * (x * math.cos(turn) + y * math.sin(turn))
    return maps_from_depth(z, rho < 0.985 * outline)


def vessel(resolution: int, generator: torch.Generator) -> ShapeMaps:
    """An open vessel (bowl, pot, vase) seen into its mouth: a convex outer wall around a concave
    cavity, the mouth off-centre as a tilted view shows it, with a raised lip."""
    u = lambda *shape: torch.rand(*shape, generator=generator)    # noqa: E731
    x, y, phi, rho = _plane(resolution)
    k = torch.arange(1, 4, dtype=torch.float32)
    outline = 0.6 + 0.3 * u(1) + ((u(3) - 0.5) * 0.15 / k * torch.cos(
        k * phi[..., None] + 2 * math.pi * u(3))).sum(-1)
    size = float(outline.mean())
    z = (0.3 + 0.7 * u(1)) * size * torch.sqrt(1 - (rho / outline).clamp(max=1) ** 2)
    mouth = (0.35 + 0.45 * u(1)) * size
    cx, cy = (u(2) - 0.5) * 0.6 * (size - mouth)
    rm = torch.hypot(x - cx, y - cy) / mouth
    depth = (0.3 + 0.9 * u(1)) * mouth
    z = z - depth * (1 - rm ** 2).clamp_min(0) ** (1 + u(1))
    lip = 0.15 * u(1) * mouth
    z = z + lip * torch.exp(-((rm - 1) ** 2) / (2 * 0.08 ** 2))
    return maps_from_depth(z, rho < 0.985 * outline)


def relief(resolution: int, generator: torch.Generator) -> ShapeMaps:
    """A tablet or relief: a tilted slab, seen face on, with raised and carved patches and grooves
    whose sharp edges cast shadows."""
    u = lambda *shape: torch.rand(*shape, generator=generator)    # noqa: E731
    x, y, _, _ = _plane(resolution)
    across, along = _turned(x, y, (u(1) - 0.5) * 0.6)
    half_w, half_h = 0.55 + 0.35 * u(1), 0.55 + 0.35 * u(1)
    mask = (across.abs() < half_w) & (along.abs() < half_h)
    tilt = (u(2) - 0.5) * 0.5
    z = 0.3 + tilt[0] * x + tilt[1] * y
    for _ in range(int(4 + 10 * u(1))):
        cx, cy = (u(2) - 0.5) * 1.6
        rx, ry = 0.04 + 0.3 * u(2)
        a, b = _turned(x - cx, y - cy, math.pi * float(u(1)))
        a, b = a / rx, b / ry
        edge = 0.02 + 0.15 * u(1)                         # soft (rounded) to sharp (stepped) edges
        height = (u(1) - 0.45) * 0.25 * min(float(rx), float(ry)) / 0.1
        z = z + height * torch.sigmoid((1 - torch.hypot(a, b)) / edge)
    return maps_from_depth(z, mask)


def slab(resolution: int, generator: torch.Generator) -> ShapeMaps:
    """A clay tablet, plaque or coin: a thin slab whose edges round off, low reliefs a few
    hundredths of its width high, short incised grooves, a slight dish or dome and at times a
    broad hollow; turned about the view axis and tilted up to 14°. Shallow where ``relief``'s
    patches are deep: under the bas-relief ambiguity the network needs both to learn how deep
    reliefs are."""
    u = lambda *shape: torch.rand(*shape, generator=generator)    # noqa: E731
    x, y, _, _ = _plane(resolution)
    across, along = _turned(x, y, math.pi * float(u(1)))
    half_w, half_h = 0.5 + 0.4 * float(u(1)), 0.5 + 0.4 * float(u(1))
    corner = (0.05 + 0.9 * float(u(1))) * min(half_w, half_h)   # a rounded rectangle to an oval
    qx, qy = across.abs() - half_w + corner, along.abs() - half_h + corner
    inside = -(torch.hypot(qx.clamp_min(0), qy.clamp_min(0)) + torch.maximum(qx, qy).clamp_max(0)
               - corner)                                          # distance from the outline
    mask = inside > 0
    edge = 0.03 + 0.15 * float(u(1))
    t = (inside / edge).clamp(0, 1)
    rounded = float(u(1))                                         # smoothstep to quarter-ellipse
    profile = (1 - rounded) * t * t * (3 - 2 * t) + rounded * torch.sqrt(1 - (1 - t) ** 2)
    z = edge * (0.3 + 1.2 * float(u(1))) * profile
    z = z + (float(u(1)) - 0.4) * 0.15 * (1 - (across / half_w) ** 2) * (1 - (along / half_h) ** 2)
    if float(u(1)) < 0.4:
        cx, cy = (u(2) - 0.5) * 0.6
        width = 0.15 + 0.25 * float(u(1))
        z = z - 0.25 * float(u(1)) * torch.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * width ** 2))
    for _ in range(int(11 * u(1))):                               # low raised patches
        cx, cy = (u(2) - 0.5) * 1.4
        rx, ry = 0.04 + 0.2 * u(2)
        a, b = _turned(x - cx, y - cy, math.pi * float(u(1)))
        a, b = a / rx, b / ry
        height = 0.005 * 10 ** float(u(1))                        # 0.005-0.05, log-uniform
        z = z + height * torch.sigmoid((1 - torch.maximum(a.abs(), b.abs())) / (0.05 + 0.2 * float(u(1))))
    grooves = int(150 * u(1))                                     # short incised V grooves
    start, turn = (u(grooves, 2, 1, 1) - 0.5) * 1.6, math.pi * u(grooves, 1, 1)
    length = GROOVE_LENGTH[0] + GROOVE_LENGTH[1] * u(grooves, 1, 1)
    width = GROOVE_WIDTH[0] + GROOVE_WIDTH[1] * u(grooves, 1, 1)
    depth = 0.008 + 0.025 * u(grooves, 1, 1)
    z = z - groove_depth(resolution, start, turn, length, width, depth)
    tilt = (u(2) - 0.5) * 0.5
    z = z + tilt[0] * x + tilt[1] * y
    return maps_from_depth(z, _eroded(mask))


GROOVE_LENGTH = (0.03, 0.1)    # a slab's grooves: lowest length and its random excess, view units
GROOVE_WIDTH = (0.01, 0.025)    # … and their half-width


def groove_depth(resolution: int, start: torch.Tensor, turn: torch.Tensor, length: torch.Tensor,
                 width: torch.Tensor, depth: torch.Tensor) -> torch.Tensor:
    """(R, R) the depth that G straight V grooves take out of a surface, each at most ``depth``
    deep on its centre line and nothing from ``width`` away.

    Each groove is worked out on a window of pixels around it only (its depth is exactly 0
    beyond), then spread on a (G, R, R) stack of zeros that is summed over the grooves as a
    whole-image computation would be: the result is the same to the bit, for a fraction of the
    arithmetic.

    Args:
        start: (G, 2, 1, 1) x, y of each groove's first end; turn: (G, 1, 1) its direction
            (radians, within [0, π)); length, width, depth: (G, 1, 1), view units, each
            ``length`` and ``width`` within :data:`GROOVE_LENGTH` and :data:`GROOVE_WIDTH`.
    """
    count = len(start)
    t = torch.linspace(-1, 1, resolution)                         # x of each column, −y of each row
    reach = sum(GROOVE_LENGTH) + 2 * sum(GROOVE_WIDTH)             # a groove's box, at most, per axis
    side = min(resolution, math.ceil(reach * (resolution - 1) / 2) + 4)
    cos, sin = torch.cos(turn), torch.sin(turn)
    sx, sy = start[:, 0], start[:, 1]                              # (G, 1, 1)
    low_x = torch.minimum(sx, sx + length * cos) - width           # the box's corner of least x …
    high_y = sy + length * sin + width                             # … and of greatest y (row 0)
    first_col = ((low_x + 1) * (resolution - 1) / 2).floor().long() - 1
    first_row = ((1 - high_y) * (resolution - 1) / 2).floor().long() - 1
    offsets = torch.arange(side)
    cols = (first_col.view(count, 1, 1).clamp(0, resolution - side) + offsets.view(1, 1, side)).expand(
        count, side, side)
    rows = (first_row.view(count, 1, 1).clamp(0, resolution - side) + offsets.view(1, side, 1)).expand(
        count, side, side)
    px, py = t[cols] - sx, -t[rows] - sy
    s = torch.minimum((px * cos + py * sin).clamp_min(0), length)
    distance = torch.hypot(px - s * cos, py - s * sin)
    stack = torch.zeros(count, resolution, resolution)
    stack[torch.arange(count).view(count, 1, 1).expand_as(cols), rows, cols] = \
        depth * (1 - distance / width).clamp_min(0)
    return stack.sum(0)


def sculpture(resolution: int, generator: torch.Generator) -> ShapeMaps:
    """Several blobs fused into one: where their surfaces meet, deep creases and crevices; the
    whole surface carries a fine random displacement."""
    u = lambda *shape: torch.rand(*shape, generator=generator)    # noqa: E731
    x, y, _, _ = _plane(resolution)
    z = torch.full_like(x, -torch.inf)
    for _ in range(int(2 + 4 * u(1))):
        cx, cy = (u(2) - 0.5) * 0.9
        radius = 0.25 + 0.35 * u(1)
        r = torch.hypot(x - cx, y - cy) / radius
        part = (0.5 + 0.8 * u(1)) * radius * torch.sqrt((1 - r ** 2).clamp_min(0)) + 0.3 * u(1)
        z = torch.where(r < 1, torch.maximum(z, part), z)
    mask = torch.isfinite(z)
    coarse = torch.rand(1, 1, 10, 10, generator=generator) - 0.5
    z = torch.where(mask, z, torch.zeros_like(z)) + 0.04 * float(u(1)) * F.interpolate(
        coarse, size=(resolution, resolution), mode="bicubic", align_corners=True)[0, 0]
    return maps_from_depth(z, _eroded(mask))


SHEET_JARS = 0.5   # share of jars made of one sheet: no lip, the inside the back of the outside


def jar(resolution: int, generator: torch.Generator) -> ShapeMaps:
    """A jar, vase or cup (an open surface of revolution with a random profile and wall) tilted
    0–85° away from looking into its mouth: the near lip hides part of the cavity, the far inner
    wall stands up behind it (:mod:`unps.lightnet.lathe`). A share :data:`SHEET_JARS` of them
    are one sheet with no thickness, whose mouth is a sharp edge rather than a visible lip."""
    u = lambda *shape: torch.rand(*shape, generator=generator)    # noqa: E731
    k = torch.arange(1, 4)
    waves, phases = (u(3) - 0.5) * 0.5 / k, 2 * math.pi * u(3)

    def radius(h: torch.Tensor) -> torch.Tensor:
        return 0.5 * (1 + (waves * torch.cos(math.pi * k * h[:, None] + phases)).sum(-1))

    height, floor, wall = 0.5 + 1.5 * float(u(1)), 0.05 + 0.55 * float(u(1)), 0.01 + 0.05 * float(u(1))
    sheet = float(u(1)) < SHEET_JARS        # thin glazed ware, a vase's flared mouth: no lip to see
    tilt, turn = math.radians(85) * float(u(1)), 2 * math.pi * float(u(1))
    extent = 1.8 * (0.75 + 0.25 * float(u(1)))                    # of the view's width 2
    return ShapeMaps(*lathe.jar_view(radius, height, floor, 0.0 if sheet else wall, tilt, turn,
                                     extent, resolution))


SHAPES = {"blob": blob, "vessel": vessel, "relief": relief, "slab": slab, "sculpture": sculpture,
          "jar": jar, "dish": dish}


def draw_shape(weights: dict[str, float], resolution: int, generator: torch.Generator,
               family: str | None = None) -> ShapeMaps:
    """A shape from one of :data:`SHAPES`, drawn by weight (or of ``family`` if given)."""
    if family is None:
        names = [name for name, weight in weights.items() if weight > 0]
        p = torch.tensor([weights[name] for name in names], dtype=torch.float64)
        family = names[0] if len(names) == 1 else \
            names[int(torch.multinomial(p / p.sum(), 1, generator=generator))]
    return SHAPES[family](resolution, generator)


def check_weights(weights: dict[str, float], known, what: str) -> None:
    """Weights name only known families, are ≥ 0 and not all 0 (an ``InputError`` otherwise)."""
    unknown = set(weights) - set(known)
    if unknown:
        raise InputError(f"{what}: unknown {sorted(unknown)}; expected some of {list(known)}")
    if any(w < 0 for w in weights.values()) or sum(weights.values()) <= 0:
        raise InputError(f"{what}: weights must be >= 0 and not all 0, got {dict(weights)}")


def _plane(resolution: int) -> tuple[torch.Tensor, ...]:
    """x, y, azimuth and radius of every pixel, (R, R) each, over [−1, 1]² (row 0 at y = 1)."""
    t = torch.linspace(-1, 1, resolution)
    y, x = -t[:, None].expand(resolution, resolution), t[None, :].expand(resolution, resolution)
    return x, y, torch.atan2(y, x), torch.hypot(x, y)


def _star_outline(phi: torch.Tensor, generator: torch.Generator) -> torch.Tensor:
    """(R, R) radius of a random star-shaped outline at each pixel's azimuth ``phi``: a circle of
    radius 0.55–0.9 with five harmonics."""
    u = lambda *shape: torch.rand(*shape, generator=generator)    # noqa: E731
    k = torch.arange(1, 6, dtype=torch.float32)
    return 0.55 + 0.35 * u(1) + ((u(5) - 0.5) * 0.4 / k * torch.cos(
        k * phi[..., None] + 2 * math.pi * u(5))).sum(-1)


def _turned(x: torch.Tensor, y: torch.Tensor, angle) -> tuple[torch.Tensor, torch.Tensor]:
    """Coordinates along axes turned by ``angle`` (radians, a float or a one-element tensor)."""
    c, s = math.cos(angle), math.sin(angle)
    return x * c + y * s, -x * s + y * c


def _eroded(mask: torch.Tensor) -> torch.Tensor:
    """The mask less its one-pixel border (whose normals the central differences smear)."""
    return -F.max_pool2d(-mask[None, None].float(), 3, 1, 1)[0, 0] > 0.5


def maps_from_depth(z: torch.Tensor, mask: torch.Tensor) -> ShapeMaps:
    """Normals of a height field z over [−1, 1]² (row 0 at y = 1) by central differences."""
    pitch = 2 / (z.shape[0] - 1)
    dz_dy_rows, dz_dx = torch.gradient(z, spacing=pitch)
    normals = F.normalize(torch.stack([-dz_dx, dz_dy_rows, torch.ones_like(z)], -1), dim=-1)
    return ShapeMaps(normals * mask[..., None], torch.where(mask, z, torch.zeros_like(z)), mask)


SHADOW_STEPS = 24
"""Samples along each shadow ray of the training data."""


def cast_shadows(maps: ShapeMaps, lights: torch.Tensor, steps: int = SHADOW_STEPS) -> torch.Tensor:
    """(n, H, W) bool: which object pixels each of the (n, 3) unit ``lights`` cannot see
    (:func:`unps.geometry.cast_shadows` on the maps' depth in view units)."""
    return geometry.cast_shadows(maps.depth, maps.mask, lights, 2 / (maps.depth.shape[0] - 1), steps)


def plan_shadows(depth: torch.Tensor, mask: torch.Tensor, lights: torch.Tensor) -> geometry.ShadowPlan:
    """The shadow march of B shapes' (B, H, W) depth and mask under their (B, n, 3) lights, all on
    the CPU, planned as :func:`cast_shadows` marches each (:func:`unps.geometry.plan_shadows`;
    :func:`unps.geometry.march_shadows` runs it)."""
    return geometry.plan_shadows(depth, mask, lights, 2 / (depth.shape[1] - 1), SHADOW_STEPS)

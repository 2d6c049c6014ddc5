"""Procedural shapes of the synthetic benchmark subjects, built in code.

Frame: x right, y up, z toward the camera, which looks down −z orthographically at the
square [−1, 1]²; every shape fits inside it. Each builder is a pure function of its
parameters, so one config always yields the same mesh.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from matplotlib.path import Path as PolygonPath
from scipy.spatial import cKDTree

from unps.geometry import depth_to_mesh


@dataclass(frozen=True, eq=False)
class Mesh:
    """A triangle mesh: (V, 3) float32 vertices, (F, 3) int32 faces."""

    vertices: np.ndarray
    faces: np.ndarray

    def vertex_normals(self) -> np.ndarray:
        """(V, 3) float32 smooth normals (face normals averaged at each vertex)."""
        mesh = trimesh.Trimesh(self.vertices, self.faces, process=False)
        return np.asarray(mesh.vertex_normals, dtype=np.float32)

    def planar_uv(self) -> np.ndarray:
        """(V, 2) texture coordinates projected along the view: u = (x + 1)/2, v = (y + 1)/2."""
        return ((self.vertices[:, :2] + 1) / 2).astype(np.float32)


def _mesh(vertices, faces) -> Mesh:
    return Mesh(np.asarray(vertices, np.float32), np.asarray(faces, np.int32))


def _grid(resolution: int) -> tuple[np.ndarray, np.ndarray]:
    """x, y coordinates of a (resolution, resolution) grid over [−1, 1]², row 0 at the top."""
    t = np.linspace(-1, 1, resolution)
    return t[None, :].repeat(resolution, 0), -t[:, None].repeat(resolution, 1)


def height_field_mesh(z: np.ndarray, inside: np.ndarray) -> Mesh:
    """Mesh of the height field z over the grid cells where ``inside`` holds (see :func:`_grid`)."""
    n = z.shape[0]
    vertices, faces = depth_to_mesh(z, inside)
    vertices[:, 0] = -1 + 2 * vertices[:, 0] / (n - 1)
    vertices[:, 1] = 1 + 2 * vertices[:, 1] / (n - 1)
    return _mesh(vertices, faces)


def parametric_mesh(points: np.ndarray, wrap: bool = False) -> Mesh:
    """Mesh of a grid of points (A, B, 3), two triangles per cell; ``wrap`` closes the B axis."""
    a, b = points.shape[:2]
    index = np.arange(a * b).reshape(a, b)
    if wrap:
        index = np.concatenate([index, index[:, :1]], axis=1)
    q = np.stack([index[:-1, :-1], index[1:, :-1], index[1:, 1:], index[:-1, 1:]], -1).reshape(-1, 4)
    faces = np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])
    return _mesh(points.reshape(-1, 3), faces)


def merge(*meshes: Mesh) -> Mesh:
    offsets = np.cumsum([0] + [len(m.vertices) for m in meshes[:-1]])
    return _mesh(np.concatenate([m.vertices for m in meshes]),
                 np.concatenate([m.faces + o for m, o in zip(meshes, offsets)]))


def gaussian(x, y, cx, cy, sx, sy, amplitude):
    return amplitude * np.exp(-((x - cx) ** 2 / (2 * sx ** 2) + (y - cy) ** 2 / (2 * sy ** 2)))


# the subjects ----------------------------------------------------------------------------

def sphere(radius: float = 0.85, subdivisions: int = 5) -> Mesh:
    """The calibration sphere."""
    m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return _mesh(m.vertices, m.faces)


def golf_ball(radius: float = 0.85, dimples: int = 300, dimple_radius: float = 0.085,
              dimple_depth: float = 0.025, subdivisions: int = 6, seed: int = 0) -> Mesh:
    """A sphere covered with spherical-cap dimples on a Fibonacci lattice (randomly rotated)."""
    m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    k = np.arange(dimples) + 0.5
    polar = np.arccos(1 - 2 * k / dimples)
    azimuth = np.pi * (1 + 5 ** 0.5) * k
    centres = np.stack([np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth),
                        np.cos(polar)], 1)
    rotation = trimesh.transformations.random_rotation_matrix(
        rand=np.random.default_rng(seed).random(3))[:3, :3]
    centres = centres @ rotation.T
    directions = np.asarray(m.vertices)
    distance, _ = cKDTree(centres).query(directions)       # chord length on the unit sphere
    a = dimple_radius / radius
    dent = np.where(distance < a, dimple_depth * (1 - (distance / a) ** 2), 0)
    return _mesh(directions * (radius - dent)[:, None], m.faces)


def face(resolution: int = 320, depth: float = 0.45, seed: int = 0) -> Mesh:
    """A face relief: an ellipsoidal dome with eye sockets, brows, a nose, mouth, cheeks, chin.

    The nose stands ~0.25 above its surroundings and the sockets sink ~0.15, so both cast
    shadows under oblique light.
    """
    rng = np.random.default_rng(seed)
    x, y = _grid(resolution)
    rho2 = (x / 0.7) ** 2 + (y / 0.9) ** 2
    z = depth * np.sqrt(np.maximum(1 - rho2, 0))
    j = lambda v: v * rng.uniform(0.9, 1.1)                  # noqa: E731 (per-feature jitter)
    features = [  # (cx, cy, sx, sy, amplitude)
        (-0.27, 0.18, 0.12, 0.08, -0.16), (0.27, 0.18, 0.12, 0.08, -0.16),      # eye sockets
        (-0.27, 0.18, 0.05, 0.04, 0.06), (0.27, 0.18, 0.05, 0.04, 0.06),        # eyes
        (-0.28, 0.34, 0.15, 0.04, 0.05), (0.28, 0.34, 0.15, 0.04, 0.05),        # brows
        (0.0, 0.02, 0.06, 0.2, 0.2), (0.0, -0.14, 0.07, 0.05, 0.08),            # nose, tip
        (-0.06, -0.2, 0.03, 0.02, -0.04), (0.06, -0.2, 0.03, 0.02, -0.04),      # nostrils
        (0.0, -0.4, 0.17, 0.02, -0.05), (0.0, -0.37, 0.14, 0.025, 0.03),        # mouth, lip
        (0.0, -0.45, 0.12, 0.025, 0.03),
        (-0.36, -0.14, 0.14, 0.12, 0.05), (0.36, -0.14, 0.14, 0.12, 0.05),      # cheeks
        (0.0, -0.68, 0.12, 0.08, 0.05),                                          # chin
    ]
    for cx, cy, sx, sy, amp in features:
        z = z + gaussian(x, y, cx + rng.uniform(-0.01, 0.01), cy, sx, sy, j(amp)) * (rho2 < 1)
    return height_field_mesh(z, rho2 < 0.995)


def _rounded_rectangle_distance(x, y, half_w, half_h, corner):
    """Signed distance to a rounded rectangle (negative inside)."""
    qx, qy = np.abs(x) - half_w + corner, np.abs(y) - half_h + corner
    outside = np.hypot(np.maximum(qx, 0), np.maximum(qy, 0))
    return outside + np.minimum(np.maximum(qx, qy), 0) - corner


def wedge(x, y, head, angle, length, width, depth):
    """A cuneiform wedge impression: V-shaped, deepest at its head, vanishing at its tail."""
    d = np.array([np.cos(angle), np.sin(angle)])
    s = (x - head[0]) * d[0] + (y - head[1]) * d[1]
    t = -(x - head[0]) * d[1] + (y - head[1]) * d[0]
    along = np.clip(1 - s / length, 0, 1) * (s >= 0)
    half = width / 2 * along
    across = np.clip(1 - np.abs(t) / np.maximum(half, 1e-9), 0, 1)
    return depth * along * across


def tablet(resolution: int = 320, concavity: float = 0.2, wedges: int = 70,
           reliefs: int = 5, relief_height: float = 0.03, seed: int = 0) -> Mesh:
    """A clay tablet: bevelled slab, optional central concavity, raised reliefs, rows of wedges."""
    rng = np.random.default_rng(seed)
    x, y = _grid(resolution)
    sd = _rounded_rectangle_distance(x, y, 0.78, 0.9, 0.15)
    bevel = np.clip(-sd / 0.12, 0, 1)
    z = 0.12 * bevel * bevel * (3 - 2 * bevel) + 0.05 * (1 - (x / 0.8) ** 2) * (1 - (y / 0.9) ** 2)
    z -= concavity * np.exp(-(x ** 2 + y ** 2) / (2 * 0.3 ** 2))
    for _ in range(reliefs):                                        # raised rectangles
        cx, cy = rng.uniform(-0.55, 0.55), rng.uniform(-0.7, 0.7)
        hw, hh = rng.uniform(0.06, 0.15), rng.uniform(0.04, 0.1)
        r = np.clip(-_rounded_rectangle_distance(x - cx, y - cy, hw, hh, 0.02) / 0.02, 0, 1)
        z += relief_height * r
    rows = np.linspace(-0.75, 0.75, 9)
    for _ in range(wedges):
        head = (rng.uniform(-0.65, 0.65), rows[rng.integers(len(rows))] + rng.uniform(-0.02, 0.02))
        angle = rng.choice([-np.pi / 2, 0.0, -np.pi / 4]) + rng.uniform(-0.15, 0.15)
        z -= wedge(x, y, head, angle, rng.uniform(0.06, 0.1), rng.uniform(0.03, 0.045),
                   rng.uniform(0.015, 0.03))
    return height_field_mesh(z, sd < -0.004)


def broken_pot(resolution: int = 320, radius: float = 0.9, pieces: int = 9,
               reach: tuple[float, float] = (0.78, 0.93), rings: float = 0.002,
               seed: int = 0) -> Mesh:
    """A fragment of a pot's shell seen from inside: a bowl concave toward the camera.

    Its outline is a star polygon with straight break edges, its corners ``reach`` from the
    axis (up the steep wall near ``radius``); throwing rings of amplitude ``rings`` ripple
    the inside.
    """
    rng = np.random.default_rng(seed)
    x, y = _grid(resolution)
    rho = np.hypot(x, y)
    z = radius - np.sqrt(np.maximum(radius ** 2 - rho ** 2, 0)) + rings * np.sin(2 * np.pi * rho / 0.08)
    corners = np.sort(rng.uniform(0, 2 * np.pi, pieces))
    distance = rng.uniform(*reach, pieces)
    px, py = distance * np.cos(corners), distance * np.sin(corners)
    inside = PolygonPath(np.stack([px, py], 1)).contains_points(
        np.stack([x.ravel(), y.ravel()], 1)).reshape(x.shape)
    return height_field_mesh(z, inside & (rho < 0.985 * radius))


def rose(layers: int = 6, seed: int = 0) -> Mesh:
    """Concentric, outward-flaring petals on a deep base: gaps, occlusions, discontinuities."""
    rng = np.random.default_rng(seed)
    sheets = []
    for i in range(layers):
        count = 3 + i // 2
        span = 2 * np.pi / count * rng.uniform(0.75, 0.9)
        r0, flare = 0.08 + 0.12 * i, 0.12 + 0.04 * i
        top = 0.5 - 0.07 * i
        phase = rng.uniform(0, 2 * np.pi)
        t = np.linspace(0, 1, 30)[:, None]
        for k in range(count):
            u = np.linspace(0, 1, 40)[None, :]
            theta = phase + k * 2 * np.pi / count + span * u
            r = (r0 + flare * t ** 2) * (1 + 0.1 * np.sin(np.pi * u))
            z = -0.5 + (top + 0.5) * t * (1 - 0.15 * np.sin(np.pi * u) * t)
            sheets.append(parametric_mesh(np.stack([r * np.cos(theta), r * np.sin(theta),
                                                    z + 0 * u], -1)))
    theta = np.linspace(0, 2 * np.pi, 96, endpoint=False)
    rr = np.linspace(0, 0.95, 20)[:, None]
    base = np.stack([rr * np.cos(theta), rr * np.sin(theta), np.full((20, 96), -0.5)], -1)
    return fit_to_view(merge(*sheets, parametric_mesh(base, wrap=True)))


def fit_to_view(mesh: Mesh, extent: float = 0.92) -> Mesh:
    """Centre the mesh's x–y bounding box on the view axis and scale it to ±extent."""
    v = mesh.vertices.astype(np.float64)
    lo, hi = v[:, :2].min(0), v[:, :2].max(0)
    v[:, :2] -= (lo + hi) / 2
    v *= extent / (np.abs(v[:, :2]).max())
    return _mesh(v, mesh.faces)

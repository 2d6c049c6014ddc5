"""Surfaces of revolution: vases, goblets and bowls, turned about their own axis and tilted
toward the camera so that their hollows show.

A vessel is built upright about the y axis (its mouth up, +y), then tilted by ``tilt_deg`` about
x (the mouth toward the camera) and turned by ``turn_deg`` about the view axis z. Frame: x right,
y up, z toward the camera, which looks down −z orthographically at the square [−1, 1]²; every
vessel is scaled into it (:func:`unps.synthetic.shapes.fit_to_view`).
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicSpline

from unps.synthetic.shapes import Mesh, fit_to_view, merge, parametric_mesh


def revolve(radii: np.ndarray, heights: np.ndarray, segments: int) -> Mesh:
    """The surface swept by the profile points (r_k, y_k) turning about the y axis.

    Args:
        radii, heights: (K,) the profile, in order along the surface; a radius of 0 closes it
            on the axis.
        segments: points around each ring.
    """
    theta = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    points = np.stack([radii[:, None] * np.cos(theta), heights[:, None].repeat(segments, 1),
                       radii[:, None] * np.sin(theta)], -1)
    return parametric_mesh(points, wrap=True)


def posed(mesh: Mesh, tilt_deg: float, turn_deg: float = 0.0) -> Mesh:
    """The upright mesh tilted by ``tilt_deg`` about x (its top toward the camera), turned by
    ``turn_deg`` about z and scaled into the view."""
    t, u = np.radians(tilt_deg), np.radians(turn_deg)
    tilt = np.array([[1, 0, 0], [0, np.cos(t), -np.sin(t)], [0, np.sin(t), np.cos(t)]])
    turn = np.array([[np.cos(u), -np.sin(u), 0], [np.sin(u), np.cos(u), 0], [0, 0, 1]])
    turned = (mesh.vertices @ (turn @ tilt).T).astype(np.float32)
    return fit_to_view(Mesh(turned, mesh.faces))


def vase(tilt_deg: float = 50.0, height: float = 1.5, segments: int = 160, rings: int = 120,
         seed: int = 0, turn_deg: float = 0.0) -> Mesh:
    """A wide-mouthed vase of one sheet (closed bottom, open top, no lip), its top tilted toward
    the camera so that the concave inside is visible."""
    h = np.linspace(0, 1, rings)
    r = vase_profile(seed)(h)
    bottom = np.linspace(0, r[0], 12)[:-1]
    mesh = merge(revolve(r, h * height, segments),
                 revolve(np.concatenate([bottom, r[:1]]), np.zeros(12), segments))
    return posed(mesh, tilt_deg, turn_deg)


def vase_profile(seed: int = 0) -> CubicSpline:
    """The :func:`vase`'s outline: a spline from heights as shares of the vase's height, in
    [0, 1], to radii in the mesh's units (the default height, 1.5, is about twice the width)."""
    rng = np.random.default_rng(seed)
    return CubicSpline([0, 0.15, 0.4, 0.7, 0.85, 1.0],
                       np.array([0.22, 0.36, 0.44, 0.34, 0.32, 0.42]) * rng.uniform(0.95, 1.05))


def goblet(tilt_deg: float = 30.0, turn_deg: float = 0.0, cup_radius: float = 0.45,
           cup_depth: float = 0.55, stem_radius: float = 0.035, stem_height: float = 0.6,
           foot_radius: float = 0.32, wall: float = 0.02, segments: int = 128) -> Mesh:
    """A goblet: a rounded cup with a thin rim, on a thin stem over a flat foot, as one closed
    surface (the cup's outside and inside meet at the rim)."""
    t = np.linspace(0, 1, 40)
    cup_outer = cup_radius * np.sin(t * np.pi / 2) ** 0.8
    cup_y = stem_height + cup_depth * (1 - np.cos(t * np.pi / 2))
    inner = np.maximum(cup_outer[::-1] - wall, 0)
    inner_y = cup_y[::-1] + wall
    foot = np.linspace(0, foot_radius, 12)
    radii = np.concatenate([foot, [foot_radius, stem_radius * 2.5, stem_radius, stem_radius],
                            np.maximum(cup_outer, stem_radius)[1:], inner])
    heights = np.concatenate([np.zeros(12), [0.03, 0.06, 0.12, stem_height - 0.04], cup_y[1:],
                              inner_y])
    return posed(revolve(radii, heights, segments), tilt_deg, turn_deg)


def bowl(tilt_deg: float = 40.0, turn_deg: float = 0.0, radius: float = 0.8, depth: float = 0.45,
         wall: float = 0.03, segments: int = 128) -> Mesh:
    """A shallow bowl with a rounded rim, seen into from above: its inside casts shadows on
    itself under oblique light."""
    t = np.linspace(0, 1, 40)
    outer_r, outer_y = radius * np.sin(t * np.pi / 2), depth * (1 - np.cos(t * np.pi / 2))
    inner_r = np.maximum(outer_r[::-1] - wall, 0)
    inner_y = outer_y[::-1] + wall
    radii = np.concatenate([outer_r, [radius + wall / 2], inner_r])
    heights = np.concatenate([outer_y, [depth + wall], inner_y])
    return posed(revolve(radii, heights, segments), tilt_deg, turn_deg)

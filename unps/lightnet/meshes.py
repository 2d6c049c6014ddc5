"""Meshes as scenes for the light network's training data: normal and depth maps of every mesh in
a folder, seen from random directions (rendered by Mitsuba's ground-truth pass).

Frame: x right, y up, z toward the camera; the orthographic view covers [−1, 1]², so one
pixel is 2 / resolution units and depth is in the same units.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import torch

from unps.errors import InputError
from unps.lightnet.shapes import ShapeMaps


def mesh_views(folder: str | os.PathLike, resolution: int, views: int, seed: int) -> list[ShapeMaps]:
    """Normal and depth maps of every mesh in a folder (.obj, .ply) from random directions."""
    import trimesh

    from unps.synthetic.render import render_ground_truth
    from unps.synthetic.shapes import Mesh, fit_to_view

    files = sorted(p for p in Path(folder).expanduser().iterdir()
                   if p.suffix.lower() in (".obj", ".ply"))
    if not files:
        raise InputError(f"{folder}: no .obj or .ply meshes for the light network's training data")
    rng = np.random.default_rng(seed)
    out = []
    for path in files:
        loaded = trimesh.load(path, force="mesh", process=False)
        vertices = np.asarray(loaded.vertices, np.float64)
        vertices -= vertices.mean(0)
        for _ in range(views):
            rotation = trimesh.transformations.random_rotation_matrix(rand=rng.random(3))[:3, :3]
            mesh = fit_to_view(Mesh((vertices @ rotation.T).astype(np.float32),
                                    np.asarray(loaded.faces, np.int32)), extent=0.9)
            normals, depth, mask = render_ground_truth(mesh, resolution)
            depth = np.where(mask, depth * 2 / resolution, 0)       # pixels → view units
            out.append(ShapeMaps(torch.as_tensor(normals), torch.as_tensor(depth, dtype=torch.float32),
                                 torch.as_tensor(mask)))
    return out

"""Mesh files."""

from __future__ import annotations

import numpy as np

from unps.io.files import atomic_path


def write_ply(path, vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray | None = None,
              uv: np.ndarray | None = None) -> None:
    """Write a binary little-endian PLY mesh, atomically.

    Args:
        vertices: (V, 3) float32 positions.
        faces: (F, 3) vertex indices.
        normals: optional (V, 3) float32 vertex normals.
        uv: optional (V, 2) float32 texture coordinates.
    """
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    if normals is not None:
        fields += [("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4")]
    if uv is not None:
        fields += [("u", "<f4"), ("v", "<f4")]
    vert = np.empty(len(vertices), dtype=fields)
    vert["x"], vert["y"], vert["z"] = vertices.T
    if normals is not None:
        vert["nx"], vert["ny"], vert["nz"] = normals.T
    if uv is not None:
        vert["u"], vert["v"] = uv.T
    face = np.empty(len(faces), dtype=[("n", "u1"), ("v", "<i4", (3,))])
    face["n"], face["v"] = 3, faces
    header = ["ply", "format binary_little_endian 1.0", f"element vertex {len(vert)}"]
    header += [f"property float {name}" for name, _ in fields]
    header += [f"element face {len(face)}", "property list uchar int vertex_indices", "end_header"]
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        f.write(("\n".join(header) + "\n").encode("ascii"))
        f.write(vert.tobytes())
        f.write(face.tobytes())

"""Physically based renders of a mesh under a dome of directional lights (Mitsuba 3).

The camera is orthographic, on +z looking down −z at the square [−1, 1]², so world
coordinates are the unps frame (x right, y up, z toward the camera). A path tracer with
several bounces gives interreflections and cast shadows; ground-truth normals and depth come
from Mitsuba's AOV integrator on the same geometry.

Image formation: each light i is a directional emitter of irradiance π·e_i, so a Lambertian
surface of albedo ρ has radiance ρ·e_i·max(n·l_i, 0) — the model the solvers assume, before
shadows, interreflections and specularity.
"""

from __future__ import annotations

import logging
import tempfile
from pathlib import Path

import numpy as np
from scipy.ndimage import gaussian_filter
from tqdm.auto import tqdm

from unps.data.analytic import dome_lights
from unps.data.subject import Subject
from unps.errors import InputError
from unps.io.mesh import write_ply
from unps.synthetic.shapes import Mesh

log = logging.getLogger(__name__)

BASE_COLOUR = {"diffuse": "reflectance", "roughplastic": "diffuse_reflectance",
               "plastic": "diffuse_reflectance", "principled": "base_color"}
CAMERA_DISTANCE = 10.0
FULL_COVERAGE = 0.999   # fraction of a pixel's ground-truth samples that must hit the object
AOV_SPP = 256           # ground-truth samples per pixel: enough to tell full from partial coverage


def light_dome(count: int, max_zenith_deg: float, intensity_range: tuple[float, float],
               colour_jitter: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Directions uniform over the cap within ``max_zenith_deg`` of +z, and RGB intensities.

    Each light has its own brightness, U(intensity_range), and its own slight tint (each
    channel × U(1 − colour_jitter, 1 + colour_jitter)), as the LEDs of a real dome do.

    Returns:
        directions (n, 3) unit, surface to light; intensities (n, 3).
    """
    if count < 1:
        raise InputError(f"lights.count must be at least 1, got {count}")
    if not 0 <= max_zenith_deg < 90:
        raise InputError(f"lights.max_zenith_deg must lie in [0, 90) so every light is above the "
                         f"horizon, got {max_zenith_deg}")
    lo, hi = intensity_range
    if not 0 < lo <= hi:
        raise InputError(f"lights.intensity_range must be 0 < low <= high, got {intensity_range}")
    directions = dome_lights(count, seed, min_elevation_deg=90 - max_zenith_deg)
    rng = np.random.default_rng(seed + 7)
    brightness = rng.uniform(lo, hi, (count, 1))
    tint = rng.uniform(1 - colour_jitter, 1 + colour_jitter, (count, 3))
    return directions, (brightness * tint).astype(np.float32)


def procedural_albedo(seed: int, size: int = 256, feature: float = 0.06,
                      contrast: float = 0.3) -> np.ndarray:
    """A smooth random multiplicative texture, (size, size, 3) float32 in [1 − contrast, 1 + contrast].

    ``feature`` is the blob size as a fraction of the texture; the channels share most of
    their pattern, so it reads as tone variation with a little colour.
    """
    rng = np.random.default_rng(seed)
    shared = gaussian_filter(rng.standard_normal((size, size)), feature * size, mode="wrap")
    own = gaussian_filter(rng.standard_normal((size, size, 3)), (feature * size,) * 2 + (0,),
                          mode="wrap")
    field = shared[..., None] / shared.std() + 0.4 * own / own.std()
    return (1 + contrast * np.tanh(field / 1.5)).astype(np.float32)


def mitsuba_bsdf(material: dict, texture: dict | None) -> dict:
    """A two-sided Mitsuba BSDF dict from a material spec; lists become RGB values.

    ``texture`` (seed, feature, contrast) multiplies the base colour with
    :func:`procedural_albedo`, making the albedo vary over the surface.
    """
    import mitsuba as mi

    spec = {k: ({"type": "rgb", "value": list(v)} if isinstance(v, (list, tuple)) else v)
            for k, v in material.items()}
    if texture:
        key = BASE_COLOUR.get(material["type"])
        if key is None or not isinstance(material.get(key), (list, tuple)):
            raise InputError(f"a texture needs a material with an RGB base colour "
                             f"({', '.join(BASE_COLOUR)}), got type {material['type']!r}")
        pattern = procedural_albedo(**texture) * np.asarray(material[key], np.float32)
        spec[key] = {"type": "bitmap", "bitmap": mi.Bitmap(np.clip(pattern, 0, 0.95)), "raw": True}
    return {"type": "twosided", "bsdf": spec}


def _scene(mesh_file: Path, bsdf: dict, integrator: dict, resolution: int, spp: int,
           sampler: str, light: bool = True):
    import mitsuba as mi

    look = mi.ScalarTransform4f().look_at(origin=[0, 0, CAMERA_DISTANCE], target=[0, 0, 0],
                                          up=[0, 1, 0])
    scene = {
        "type": "scene",
        "integrator": integrator,
        "sensor": {"type": "orthographic", "to_world": look,
                   "film": {"type": "hdrfilm", "width": resolution, "height": resolution,
                            "rfilter": {"type": "box"}, "pixel_format": "rgb"},
                   "sampler": {"type": sampler, "sample_count": spp}},
        "object": {"type": "ply", "filename": str(mesh_file), "face_normals": False, "bsdf": bsdf},
    }
    if light:
        scene["light"] = {"type": "directional", "direction": [0, 0, -1.0],
                          "irradiance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}}
    return mi.load_dict(scene)


def set_variant(variant: str) -> None:
    import mitsuba as mi

    if variant not in mi.variants():
        raise InputError(f"Mitsuba variant {variant!r} is not available; available: "
                         f"{', '.join(mi.variants())} (scalar_rgb works everywhere)")
    mi.set_variant(variant)


def render_subject(name: str, mesh: Mesh, material: dict, texture: dict | None,
                   directions: np.ndarray, intensities: np.ndarray, resolution: int = 128,
                   spp: int = 64, max_depth: int = 5, variant: str = "scalar_rgb",
                   sampler: str = "stratified", seed: int = 0, progress: bool = True) -> Subject:
    """Render one image per light plus ground truth, and return the subject.

    Args:
        mesh: the object, inside the view square [−1, 1]².
        material: a Mitsuba BSDF spec (``type`` and its parameters).
        texture: optional spatially varying albedo (see :func:`mitsuba_bsdf`).
        directions: (n, 3) unit surface-to-light directions; intensities (n, 3) RGB.
        resolution: image side in pixels.
        spp: samples per pixel of each image.
        max_depth: the path tracer's longest path (2 = direct light only; more adds
            interreflections).
        variant: Mitsuba variant (``scalar_rgb`` works on every machine).
        sampler: Mitsuba sampler; ``stratified`` (spp a square) jitters within a grid, which
            integrates pixel footprints and soft highlights with far less noise than
            ``independent``.
        seed: image i is rendered with sampler seed ``seed * 1_000_003 + i``.

    Returns:
        A subject whose images are divided by the intensities, with GT normals (facing the
        camera) and depth (along +z, in pixel units) on the pixels fully covered by the object.
    """
    import mitsuba as mi

    if resolution < 4 or spp < 1 or max_depth < 2:
        raise InputError(f"render needs resolution >= 4, spp >= 1 and max_depth >= 2, got "
                         f"{resolution}, {spp}, {max_depth}")
    set_variant(variant)
    with tempfile.TemporaryDirectory() as tmp:
        mesh_file = _write_mesh(mesh, Path(tmp))
        normals, depth, mask = _ground_truth(mesh_file, resolution, seed)
        if not mask.any():
            raise InputError(f"{name}: the object covers no pixel fully at {resolution}×{resolution}")
        scene = _scene(mesh_file, mitsuba_bsdf(material, texture),
                       {"type": "path", "max_depth": max_depth}, resolution, spp, sampler)
        params = mi.traverse(scene)
        images = np.empty((len(directions), resolution, resolution, 3), np.float32)
        for i in tqdm(range(len(directions)), desc=f"rendering {name}", unit="image",
                      disable=not progress, leave=False):
            light = directions[i].astype(np.float64)
            up = [0, 1, 0] if abs(light[1]) < 0.9 else [1, 0, 0]
            params["light.to_world"] = mi.ScalarAffineTransform4f().look_at(
                origin=[0, 0, 0], target=list(-light), up=up)
            params["light.irradiance.value"] = mi.ScalarColor3f(*(np.pi * intensities[i]))
            params.update()
            images[i] = np.array(mi.render(scene, seed=seed * 1_000_003 + i))[..., :3]
    return Subject(name=name, images=images / intensities[:, None, None, :], mask=mask,
                   light_directions=directions, light_intensities=intensities,
                   normals=normals, depth=depth)


def _write_mesh(mesh: Mesh, folder: Path) -> Path:
    path = folder / "mesh.ply"
    write_ply(path, mesh.vertices, mesh.faces, mesh.vertex_normals(), mesh.planar_uv())
    return path


def _ground_truth(mesh_file: Path, resolution: int, seed: int
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    normals, depth, coverage = _traced(mesh_file, resolution, seed)
    mask = covered_whole(coverage, depth)
    normals[~mask] = 0
    return normals, np.where(mask, depth, np.nan).astype(np.float32), mask


def covered_whole(coverage: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """(H, W) bool: the pixels the object covers whole (:data:`FULL_COVERAGE` of their samples)
    with a finite depth, from :func:`_traced`'s (H, W) ``coverage`` and ``depth``."""
    return (coverage > FULL_COVERAGE) & np.isfinite(depth)


def _traced(mesh_file: Path, resolution: int, seed: int
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What the camera sees of the mesh, pixel by pixel, from Mitsuba's AOVs (no shading).

    Returns:
        normals (H, W, 3), the unit mean of the normals the pixel's samples hit, facing the
        camera (0 where none is finite); depth (H, W) along +z in pixel units of those samples
        (NaN where no finite normal or depth); coverage (H, W), the share of its samples that hit
        the object, in [0, 1].
    """
    import mitsuba as mi

    white = {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": 1.0}}
    aov = _scene(mesh_file, white, {"type": "aov", "aovs": "cc:albedo,nn:sh_normal,pp:position"},
                 resolution, AOV_SPP, "independent", light=False)
    truth = np.array(mi.render(aov, seed=seed))
    coverage, normals, position = truth[..., 0], truth[..., 3:6], truth[..., 6:9]
    # degenerate faces of a foreign mesh can leave NaN normals: such pixels are not ground truth
    finite = np.isfinite(normals).all(-1) & np.isfinite(position[..., 2])
    normals = np.where(finite[..., None], normals, 0)
    normals = normals / np.maximum(np.linalg.norm(normals, axis=-1), 1e-12)[..., None]
    normals *= np.where(normals[..., 2:] < 0, -1, 1)            # the side the camera sees
    # the AOVs average over the pixel's samples, background ones giving 0: z over coverage
    depth = np.where(finite & (coverage > 0), position[..., 2] / np.maximum(coverage, 1e-12), np.nan)
    return (normals.astype(np.float32), (depth * resolution / 2).astype(np.float32),
            np.clip(coverage, 0, 1).astype(np.float32))


def render_ground_truth(mesh: Mesh, resolution: int, variant: str = "scalar_rgb", seed: int = 0
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Normals (H, W, 3) facing the camera, depth (H, W) along +z in pixel units (NaN off the
    object) and the mask of fully covered pixels, from Mitsuba's AOVs (no shading)."""
    set_variant(variant)
    with tempfile.TemporaryDirectory() as tmp:
        return _ground_truth(_write_mesh(mesh, Path(tmp)), resolution, seed)

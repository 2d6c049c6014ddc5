"""Everything a fit leaves in its run folder; ``metrics.json`` is written last."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from unps.data.estimate import Estimate, Rendering
from unps.data.subject import Subject
from unps.geometry import depth_to_mesh
from unps.io.files import atomic_path, write_json, write_npy
from unps.io.images import write_png8
from unps.io.mesh import write_ply
from unps.io.pictures import (albedo_rgb, error_figure_png, error_rgb, labelled_rows,
                              lights_figure_png, normal_rgb, shape_figure_png, to_display)
from unps.lights import Lights, write_lights

log = logging.getLogger(__name__)


def write_fit_outputs(out: Path, subject: Subject, estimate: Estimate, depth: np.ndarray,
                      lights: Lights, metrics: dict, error: np.ndarray | None,
                      true_lights: Lights | None = None) -> None:
    """Write the mask used, normals, albedo, depth, mesh, error map, lights, TensorBoard and
    metrics.json.

    ``lights.png`` shows the lights used, against the true ones when those are known;
    ``shape.png`` the recovered surface from above and to the side, and its profiles (a dome is
    told from a bowl there at a glance: lights read inside out give the one for the other).
    With ground truth, ``normals_gt.png`` and ``error.npy`` (float16 degrees) are written too,
    and ``lights_gt.txt`` when the lights used were not the true ones: the report's
    qualitative grids and light plots read them.

    Every file is written atomically and ``metrics.json`` comes last, so its presence means
    the run finished.

    Args:
        out: the run folder.
        estimate: (H, W, 3) normals and albedo on the subject's grid.
        depth: (H, W) depth in pixel units, NaN off the mask.
        error: (H, W) angular error in degrees, when ground truth exists.
        true_lights: the subject's calibrated lights, when known and not the ones used.
    """
    mask = subject.mask
    write_png8(out / "mask.png", np.repeat(mask[..., None], 3, -1) * np.uint8(255))
    write_npy(out / "normals.npy", estimate.normals)
    write_png8(out / "normals.png", normal_rgb(estimate.normals, mask))
    write_npy(out / "albedo.npy", estimate.albedo)
    albedo_image, albedo_scale = albedo_rgb(estimate.albedo, mask)
    write_png8(out / "albedo.png", albedo_image)
    write_npy(out / "depth.npy", depth)
    vertices, faces = depth_to_mesh(depth, mask, subject.frame)
    write_ply(out / "mesh.ply", vertices, faces, normals=estimate.normals[mask])
    with atomic_path(out / "shape.png") as tmp:
        tmp.write_bytes(shape_figure_png(depth, mask, f"{subject.name}: the recovered surface"))
    write_lights(out / "lights.txt", lights)
    if true_lights is not None:
        write_lights(out / "lights_gt.txt", true_lights)
    write_lights_picture(out / "lights.png", lights, metrics, true_lights)
    if subject.normals is not None:
        write_png8(out / "normals_gt.png", normal_rgb(subject.normals, mask))
    if estimate.rendering is not None:
        write_rendering(out, estimate.rendering)
    if error is not None:
        write_npy(out / "error.npy", np.where(mask, error, np.nan).astype(np.float16))
        title = (f"{subject.name}: mean {metrics['normal_mae']:.2f}°, "
                 f"median {metrics['normal_median']:.2f}°")
        with atomic_path(out / "error.png") as tmp:
            tmp.write_bytes(error_figure_png(error, mask, title))
    _write_tensorboard(out / "tensorboard", subject, estimate, albedo_image, metrics, error)
    write_json(out / "metrics.json", {**metrics, "albedo_png_scale": albedo_scale,
                                      "frame": subject.frame.to_dict()})
    log.info("outputs written to %s", out)


def write_lights_picture(path: Path, lights: Lights, metrics: dict,
                         true_lights: Lights | None) -> None:
    """``lights.png``: where each image's light is, and its error when the true lights are known."""
    title = f"{metrics['subject']}: {len(lights.directions)} lights ({lights.source})"
    if "light_dir_mae" in metrics:
        title += f", direction error {metrics['light_dir_mae']:.2f}° on average"
    intensities = None if lights.intensities is None else lights.intensities.mean(1)
    truth = None if true_lights is None else true_lights.directions
    with atomic_path(path) as tmp:
        tmp.write_bytes(lights_figure_png(lights.directions, intensities, title, truth))


def write_rendering(out: Path, rendering: Rendering) -> None:
    """A rendering method's per-image maps, on its working grid (recorded in metrics.json):
    ``reflectance.npy`` and ``reconstruction.npy`` (n, h, w, 3) float16, and two contact sheets
    of up to 6 evenly spaced images: ``reconstruction.png`` (rows: observed, reconstructed,
    |difference|, on one scale) and ``reflectance.png``.
    """
    write_npy(out / "reflectance.npy", rendering.reflectance.astype(np.float16))
    write_npy(out / "reconstruction.npy", rendering.reconstruction.astype(np.float16))
    n = len(rendering.observed)
    picks = np.unique(np.linspace(0, n - 1, min(n, 6)).round().astype(int))
    mask = rendering.mask[..., None]
    observed, reconstructed = rendering.observed[picks] * mask, rendering.reconstruction[picks] * mask
    rows = [to_display(np.concatenate(list(r), 1), observed[:, rendering.mask])
            for r in (observed, reconstructed, np.abs(observed - reconstructed))]
    write_png8(out / "reconstruction.png",
               labelled_rows(rows, ["observed", "reconstructed", "|difference|"]))
    reflectance = rendering.reflectance[picks] * mask
    write_png8(out / "reflectance.png",
               to_display(np.concatenate(list(reflectance), 1), reflectance[:, rendering.mask]))


def _write_tensorboard(folder: Path, subject: Subject, estimate: Estimate,
                       albedo_image: np.ndarray, metrics: dict, error: np.ndarray | None) -> None:
    from torch.utils.tensorboard import SummaryWriter

    with SummaryWriter(str(folder)) as writer:
        for key, value in metrics.items():
            if isinstance(value, (int, float)) and not isinstance(value, bool):
                writer.add_scalar(f"fit/{key}", value, 0)
        writer.add_image("normals", normal_rgb(estimate.normals, subject.mask), 0, dataformats="HWC")
        writer.add_image("albedo", albedo_image, 0, dataformats="HWC")
        if error is not None:
            writer.add_image("error_0_45deg", error_rgb(error, subject.mask), 0, dataformats="HWC")

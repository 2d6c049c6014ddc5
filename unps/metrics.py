"""Accuracy measures of the field: normal angular error, light direction and intensity error."""

from __future__ import annotations

import numpy as np


def angular_error(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle in degrees between vectors along the last axis.

    Args:
        a, b: (..., 3) vectors of any non-zero length.

    Returns:
        (...,) degrees in [0, 180].

    Example:
        >>> angular_error(np.array([0, 0, 1.0]), np.array([0, 1, 1.0]))
        array(45.)
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    cos = (a * b).sum(-1) / np.maximum(np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1),
                                       1e-12)
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def normal_metrics(pred: np.ndarray, gt: np.ndarray, mask: np.ndarray) -> dict[str, float]:
    """Mean and median angular error and the fractions under 11.25°, 30° and 45°, over the mask.

    Args:
        pred, gt: (H, W, 3) normals.
        mask: (H, W) bool.
    """
    err = angular_error(pred, gt)[mask]
    return {"normal_mae": float(err.mean()), "normal_median": float(np.median(err)),
            "acc_11_25": float((err < 11.25).mean()), "acc_30": float((err < 30).mean()),
            "acc_45": float((err < 45).mean()), "slant_bias": slant_bias(pred, gt, mask)}


def slant_bias(pred: np.ndarray, gt: np.ndarray, mask: np.ndarray) -> float:
    """Mean over the mask of the predicted minus the true slant, in degrees.

    The slant is a normal's angle to the view axis +z. A positive bias means normals tilted
    away from the camera (a steeper surface): what a Lambertian reading gives when dim pixels
    are darker than the model expects (truncated 8-bit levels, Fresnel-weighted diffuse
    reflection); a negative one means a flatter surface (interreflections, reflectance maps
    that absorb shading).

    Args:
        pred, gt: (H, W, 3) normals of any non-zero length.
        mask: (H, W) bool.
    """
    view = np.array([0.0, 0.0, 1.0])
    return float((angular_error(pred[mask], view) - angular_error(gt[mask], view)).mean())


def light_direction_mae(pred: np.ndarray, gt: np.ndarray) -> float:
    """Mean angular error in degrees between (n, 3) light directions."""
    return float(angular_error(pred, gt).mean())


def light_intensity_error(pred: np.ndarray, gt: np.ndarray) -> float:
    """Scale-invariant relative intensity error (SDPS-Net's definition).

    Intensities are known only up to one global scale, so the scale s minimising
    ‖gt − s·pred‖² is fitted first; the error is the mean of |gt − s·pred| / gt.

    Args:
        pred, gt: (n,) or (n, 3) positive intensities.
    """
    pred = np.asarray(pred, dtype=np.float64).ravel()
    gt = np.asarray(gt, dtype=np.float64).ravel()
    s = (gt @ pred) / max(pred @ pred, 1e-300)
    return float(np.mean(np.abs(gt - s * pred) / gt))

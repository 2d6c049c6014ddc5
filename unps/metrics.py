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
        >>> round(float(angular_error(np.array([0, 0, 1.0]), np.array([0, 1, 1.0]))), 6)
        45.0
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
    """Mean signed error along the slant direction, in degrees: > 0 when the predicted normals
    lean further from the view axis +z than the true ones (a steeper surface), < 0 when flatter.

    At each pixel the predicted normal p is projected onto the plane of the true normal n and
    its slant direction e = ∂n/∂slant (the unit tangent at n pointing away from +z); the error
    is the angle atan2(p·e, p·n), exactly δ when p is n steepened by δ. The difference of the
    slants themselves would read any error on a surface facing the camera as steepening (no
    slant is below 0), so noise alone would pass for bias; this measure is 0 on average for
    errors that point every way. The price: a turn about the view axis by φ, which leaves the
    slant as it is, reads as a flattening of (1 − cos φ)·sin(2·slant)/2 radians (0.1° for 5°,
    1.2° for a 16.6° turn at a slant of 45°). Pixels whose true normal is the view axis itself
    (slant below 0.01°) have no slant direction and are left out.

    A positive bias is what a Lambertian reading gives when dim pixels are darker than the model
    expects (truncated 8-bit levels, Fresnel-weighted diffuse reflection); a negative one,
    interreflections or reflectance maps that absorb shading.

    Args:
        pred, gt: (H, W, 3) normals of any non-zero length.
        mask: (H, W) bool.

    Returns:
        The mean, or NaN when no pixel of the mask has a slant direction.
    """
    p = np.asarray(pred, dtype=np.float64)[mask]
    n = np.asarray(gt, dtype=np.float64)[mask]
    p = p / np.maximum(np.linalg.norm(p, axis=-1, keepdims=True), 1e-12)
    n = n / np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-12)
    sin_slant = np.linalg.norm(n[:, :2], axis=-1)
    keep = sin_slant > np.sin(np.radians(0.01))
    if not keep.any():
        return float("nan")
    p, n, sin_slant = p[keep], n[keep], sin_slant[keep]
    tilt = n[:, :2] / sin_slant[:, None]                             # unit, in the image plane
    steeper = np.concatenate([n[:, 2:] * tilt, -sin_slant[:, None]], 1)
    return float(np.degrees(np.arctan2((p * steeper).sum(-1), (p * n).sum(-1))).mean())


def light_direction_mae(pred: np.ndarray, gt: np.ndarray) -> float:
    """Mean angular error in degrees between (n, 3) light directions."""
    return float(angular_error(pred, gt).mean())


def light_slant_bias(pred: np.ndarray, gt: np.ndarray) -> float:
    """:func:`slant_bias` of (n, 3) light directions: the mean signed error of their angle from
    the view axis, in degrees; < 0 when the lights are read nearer the view axis than they are (a
    flattened reading), > 0 when read more grazing. Errors that point every way average 0.

    >>> flat = np.array([[np.sin(np.radians(28)), 0.0, np.cos(np.radians(28))]])
    >>> round(light_slant_bias(flat, np.array([[np.sin(np.radians(30)), 0.0, np.cos(np.radians(30))]])), 6)
    -2.0
    """
    gt = np.asarray(gt)
    return slant_bias(np.asarray(pred)[None], gt[None], np.ones((1, len(gt)), bool))


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

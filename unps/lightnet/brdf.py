"""Isotropic BRDFs for training data: analytic lobes, the MERL tables, and their neural fits.

Every BRDF is called with local directions (normal = +z) ``wi`` (to the light) and ``wo``
(to the camera), (..., 3) unit tensors, and returns (..., 3) RGB values f(wi, wo) in the
MERL database's units; the rendered radiance is e · f · cos θᵢ.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import torch
from torch import nn

from unps.errors import InputError

MERL_SHAPE = (90, 90, 180)                          # θ_h, θ_d, φ_d
MERL_SCALE = (1.0 / 1500, 1.15 / 1500, 1.66 / 1500)


def half_diff_angles(wi: torch.Tensor, wo: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Rusinkiewicz coordinates θ_h, θ_d, φ_d of local direction pairs (normal = +z).

    The half vector h = (wi + wo)/|·| has polar angle θ_h; d is wi seen from h: wi rotated by
    −φ_h about z and then by −θ_h about y, with polar angle θ_d and azimuth φ_d.
    """
    h = torch.nn.functional.normalize(wi + wo, dim=-1)
    theta_h = torch.acos(h[..., 2].clamp(-1, 1))
    phi_h = torch.atan2(h[..., 1], h[..., 0])
    c, s = torch.cos(phi_h), torch.sin(phi_h)
    x = c * wi[..., 0] + s * wi[..., 1]
    y = -s * wi[..., 0] + c * wi[..., 1]
    ct, st = torch.cos(theta_h), torch.sin(theta_h)
    dx, dz = ct * x - st * wi[..., 2], st * x + ct * wi[..., 2]
    return theta_h, torch.acos(dz.clamp(-1, 1)), torch.atan2(y, dx)


def ggx_lobe(wi: torch.Tensor, wo: torch.Tensor, alpha, fresnel0) -> torch.Tensor:
    """One Cook–Torrance lobe D · G · F / (4 cos θᵢ cos θₒ), (...,) for (..., 3) local directions.

    GGX distribution of roughness ``alpha``, Smith–GGX masking, Schlick Fresnel from ``fresnel0``
    (0.04: a dielectric coat; near 1: a metal); both floats or 0-d tensors.
    """
    a2 = alpha ** 2
    h = torch.nn.functional.normalize(wi + wo, dim=-1)
    cos_h, cos_i, cos_o = h[..., 2], wi[..., 2].clamp_min(1e-4), wo[..., 2].clamp_min(1e-4)
    d = a2 / (math.pi * (cos_h ** 2 * (a2 - 1) + 1) ** 2)
    g1 = lambda c: 2 * c / (c + torch.sqrt(a2 + (1 - a2) * c ** 2))   # noqa: E731
    fresnel = fresnel0 + (1 - fresnel0) * (1 - (wi * h).sum(-1).clamp(0, 1)) ** 5
    return d * g1(cos_i) * g1(cos_o) * fresnel / (4 * cos_i * cos_o)


class AnalyticBRDF(nn.Module):
    """Lambertian diffuse plus GGX / Cook–Torrance specular lobes (:func:`ggx_lobe`).

    f = ρ_d/π + Σₖ ρₖ · D(θ_h; αₖ) · G · F(θ_d; F0ₖ) / (4 cos θᵢ cos θₒ).

    Args:
        diffuse: (3,) RGB albedo.
        specular: (3,) RGB albedo of one lobe, or (k, 3) of k lobes.
        roughness: GGX α of each lobe (a float, or k of them).
        fresnel0: Schlick's F0 of each lobe; default 0.04, a dielectric coat.
    """

    def __init__(self, diffuse, specular, roughness, fresnel0=0.04):
        super().__init__()
        self.register_buffer("diffuse", torch.as_tensor(diffuse, dtype=torch.float32))
        self.register_buffer("specular", torch.as_tensor(specular, dtype=torch.float32).reshape(-1, 3))
        lobes = len(self.specular)
        self.roughness = per_lobe(roughness, lobes, "roughness")
        self.fresnel0 = per_lobe(fresnel0, lobes, "fresnel0")

    def forward(self, wi: torch.Tensor, wo: torch.Tensor) -> torch.Tensor:
        value = self.diffuse / math.pi
        for albedo, alpha, fresnel0 in zip(self.specular, self.roughness, self.fresnel0):
            value = value + albedo * ggx_lobe(wi, wo, alpha, fresnel0)[..., None]
        return value


def per_lobe(value, lobes: int, name: str) -> tuple:
    """One value per lobe: a float is shared by all; floats stay floats, tensors stay tensors."""
    values = tuple(value) if isinstance(value, (list, tuple, torch.Tensor)) else (float(value),) * lobes
    if len(values) != lobes:
        raise ValueError(f"{name}: {len(values)} values for {lobes} lobes")
    return values


def random_analytic(generator: torch.Generator) -> AnalyticBRDF:
    """A random analytic material: coloured diffuse, grey-to-tinted specular, α in [0.05, 0.6]."""
    u = torch.rand(8, generator=generator)
    diffuse = 0.1 + 0.8 * u[:3]
    specular = (0.0 + 1.5 * u[3]) * (0.7 + 0.3 * u[4:7])
    roughness = 0.05 + 0.55 * float(u[7]) ** 1.5
    return AnalyticBRDF(diffuse, specular, roughness)


# 5 % and 95 % points of diffuse + two-lobe fits to the 100 MERL materials, made and printed by
# experiments/light_estimation/merl_lobes.py: roughness of the sharper and the broader lobe, F0 of
# both, log10 of specular over diffuse albedo (luminance) and of lobe 2 over lobe 1.
MEASURED_RANGES = {"alpha1": (0.009, 0.365), "alpha2": (0.088, 0.910), "fresnel0": (0.01, 0.36),
                   "log10_specular_over_diffuse": (-0.07, 2.20), "log10_lobe2_over_lobe1": (-1.24, 1.53)}


def random_measured(generator: torch.Generator) -> AnalyticBRDF:
    """A random material in the span of measured ones: diffuse and two GGX lobes whose
    roughness, F0 and albedo ratios lie within :data:`MEASURED_RANGES` (log-uniform for the
    roughness and ratios, uniform for F0); coloured diffuse, grey-to-tinted lobes."""
    u = torch.rand(14, generator=generator)

    def log_uniform(key: str, x: torch.Tensor, low: float | None = None) -> float:
        lo, hi = MEASURED_RANGES[key]
        lo = max(lo, low) if low is not None else lo
        return float(10 ** (lo + (hi - lo) * x)) if key.startswith("log10") else \
            float(lo * (hi / lo) ** x)

    diffuse = 0.1 + 0.8 * u[:3]
    specular_total = float(diffuse.mean()) * log_uniform("log10_specular_over_diffuse", u[3])
    second_over_first = log_uniform("log10_lobe2_over_lobe1", u[4])
    first = specular_total / (1 + second_over_first)
    tints = 0.5 + 0.5 * u[5:11].reshape(2, 3)
    specular = torch.stack([first * tints[0], first * second_over_first * tints[1]])
    alpha1 = log_uniform("alpha1", u[11])
    alpha2 = log_uniform("alpha2", u[12], low=alpha1)
    lo, hi = MEASURED_RANGES["fresnel0"]
    fresnel0 = lo + (hi - lo) * torch.rand(2, generator=generator)
    return AnalyticBRDF(diffuse, specular, (alpha1, alpha2), tuple(map(float, fresnel0)))


class TabulatedBRDF(nn.Module):
    """A MERL measured BRDF: a 90×90×180 table per colour over (θ_h, θ_d, φ_d).

    Indexing follows MERL's reference reader: θ_h non-linearly (√(θ_h / 90°) · 90), θ_d
    linearly, φ_d over [0°, 180°) using reciprocity; the colour scales 1/1500, 1.15/1500,
    1.66/1500 are applied, negative (unmeasured) entries read as 0.
    """

    def __init__(self, table: np.ndarray):
        super().__init__()
        if table.shape != (3,) + MERL_SHAPE:
            raise ValueError(f"expected a (3, 90, 90, 180) table, got {table.shape}")
        scaled = np.maximum(table, 0) * np.asarray(MERL_SCALE)[:, None, None, None]
        self.register_buffer("table", torch.as_tensor(scaled, dtype=torch.float32).flatten(1))

    def forward(self, wi: torch.Tensor, wo: torch.Tensor) -> torch.Tensor:
        theta_h, theta_d, phi_d = half_diff_angles(wi, wo)
        th = (torch.sqrt(theta_h.clamp_min(0) / (math.pi / 2)) * 90).long().clamp(0, 89)
        td = (theta_d / (math.pi / 2) * 90).long().clamp(0, 89)
        phi = torch.where(phi_d < 0, phi_d + math.pi, phi_d)
        pd = (phi / math.pi * 180).long().clamp(0, 179)
        index = (th * 90 + td) * 180 + pd
        return self.table[:, index].movedim(0, -1)


def read_merl_binary(path: str | os.PathLike) -> TabulatedBRDF:
    """Read a MERL ``.binary`` file: three int32 dimensions (90, 90, 180), then 3×90×90×180
    float64 values in R, G, B blocks."""
    path = Path(path)
    data = path.read_bytes() if path.is_file() else None
    if data is None:
        raise InputError(f"{path}: MERL BRDF file not found")
    dims = np.frombuffer(data[:12], dtype="<i4") if len(data) >= 12 else np.zeros(3)
    expected = 12 + 8 * 3 * int(np.prod(MERL_SHAPE))
    if tuple(dims) != MERL_SHAPE or len(data) != expected:
        raise InputError(f"{path}: not a MERL BRDF (expected dimensions 90 90 180 and {expected} "
                         f"bytes, found {tuple(int(d) for d in dims)} and {len(data)} bytes)")
    table = np.frombuffer(data[12:], dtype="<f8").reshape((3,) + MERL_SHAPE)
    return TabulatedBRDF(table)


class NeuralBRDF(nn.Module):
    """A neural fit of a MERL material (Sztrajman et al. 2021): Dense 6→21→21→3, exp(x) − 1.

    Input: the half vector with φ_h = 0, h = (sin θ_h, 0, cos θ_h), and the difference vector
    d = (sin θ_d cos φ_d, sin θ_d sin φ_d, cos θ_d). Output: RGB in MERL's units.
    """

    def __init__(self, layers: list[tuple[np.ndarray, np.ndarray]]):
        super().__init__()
        self.layers = nn.ModuleList()
        for kernel, bias in layers:
            linear = nn.Linear(*kernel.shape)
            with torch.no_grad():
                linear.weight.copy_(torch.as_tensor(kernel.T))
                linear.bias.copy_(torch.as_tensor(bias))
            self.layers.append(linear)
        self.requires_grad_(False)                   # a fixed material, not a model to train

    def forward(self, wi: torch.Tensor, wo: torch.Tensor) -> torch.Tensor:
        theta_h, theta_d, phi_d = half_diff_angles(wi, wo)
        st = torch.sin(theta_d)
        x = torch.stack([torch.sin(theta_h), torch.zeros_like(theta_h), torch.cos(theta_h),
                         st * torch.cos(phi_d), st * torch.sin(phi_d), torch.cos(theta_d)], -1)
        for i, layer in enumerate(self.layers):
            x = layer(x)
            if i < len(self.layers) - 1:
                x = torch.relu(x)
        return torch.expm1(x).clamp_min(0)


def read_neural_brdf(path: str | os.PathLike) -> NeuralBRDF:
    """Read a neural BRDF fit (``<material>.h5``, Keras weights ``dense_k/dense_k/kernel:0``)."""
    import h5py

    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: neural BRDF file not found")
    try:
        with h5py.File(path, "r") as f:
            layers = [(np.asarray(f[f"dense_{k}/dense_{k}/kernel:0"], np.float32),
                       np.asarray(f[f"dense_{k}/dense_{k}/bias:0"], np.float32)) for k in (1, 2, 3)]
    except (OSError, KeyError) as e:
        raise InputError(f"{path}: not a neural BRDF fit with layers dense_1…dense_3 ({e})") from None
    return NeuralBRDF(layers)

"""The explicit image model that self-calibration fits: a surface, its reflectance and the lights.

Every pixel p of the working grid under image i is rendered as

    X̃_ip = V_ip · e_i · max(n_p·l_i, 0) · (ρ_p + Σ_k w_jk · exp(κ_k (n_p·h_i − 1))),  j = j(p)

with V_ip 0 where the depth map casts a shadow on p from light i and 1 elsewhere
(:meth:`SelfCalibrationModel.visibility`), n_p the normal of a depth map (so the normals are
integrable), ρ_p an RGB diffuse albedo,
w_jk ≥ 0 the weights of K spherical-Gaussian specular lobes of fixed sharpness κ_k, shared by the
pixels of one material j (the object's pixels are split into a few materials by colour before the
fit, :func:`unps.lights.selfcal.material_labels`), h_i the half vector between l_i and the view
v = (0, 0, 1) (orthographic), and (l_i, e_i) the direction and intensity of light i.

The lights are parameterised around a first guess s̃_i (the light network's directions; the
images are divided by its intensities): s_i = (s̃_i + ε_i)·A, l_i = s_i / |s_i|, e_i = |s_i|
(normalised to geometric mean 1). The 3×3 matrix A carries what all the lights share, and is split
as A = [c_x | c_y | μ c_x + ν c_y + λ e_z]: the columns c_x, c_y are fixed by the integrability of
the depth map, while (μ, ν, λ) is the generalised bas-relief (GBR) transform that integrable
Lambertian shading leaves free and only the specular lobes (and the pull toward the first guess,
:mod:`unps.lights.prior`) pin down. ε_i is a small per-light correction.

Frame: x right (+col), y up (−row), z toward the camera; depth in pixels of the working grid.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from unps.geometry import cast_shadows

VIEW = (0.0, 0.0, 1.0)
MIN_EXPONENT = -60.0   # lobes below e⁻⁶⁰ are cut: float32 denormals would make the CPU crawl


def normals_from_depth(depth: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Unit normals of a depth map at its object pixels, from one-sided differences to the
    neighbours that are on the object (their mean where both are).

    Args:
        depth: (H, W) depth along +z in pixel units.
        mask: (H, W) bool.

    Returns:
        (m, 3) unit normals at ``mask``'s pixels in row-major order, (−∂z/∂x, −∂z/∂y, 1) normalised.

    Example:
        >>> ramp = torch.arange(4.0).repeat(3, 1)        # z = col: rises to the right
        >>> normals_from_depth(ramp, torch.ones(3, 4, dtype=torch.bool))[0]
        tensor([-0.7071,  0.0000,  0.7071])
    """
    on = mask.to(depth.dtype)
    dz_dcol, dz_drow = _mean_slope(depth, on), _mean_slope(depth.T, on.T).T
    normals = torch.stack([-dz_dcol, dz_drow, torch.ones_like(depth)], -1)[mask]   # ∂z/∂y = −∂z/∂row
    return F.normalize(normals, dim=-1)


def _mean_slope(z: torch.Tensor, on: torch.Tensor) -> torch.Tensor:
    """(H, W) slope of z along its last axis at every pixel: the mean of the one-sided
    differences to the neighbours that are on the object (``on`` is 1 there, 0 elsewhere)."""
    both = on[:, 1:] * on[:, :-1]
    step = (z[:, 1:] - z[:, :-1]) * both
    total = F.pad(step, (1, 0)) + F.pad(step, (0, 1))
    return total / (F.pad(both, (1, 0)) + F.pad(both, (0, 1))).clamp_min(1)


class SpecularLobes(torch.autograd.Function):
    """Σ_k w_k · exp(max(κ_k (c − 1), ``MIN_EXPONENT``)) with its gradient written out; the
    weights shared by every pixel, or one set per pixel.

    One tensor of K·m·n exponentials is made in the forward pass, in place, and reused by the
    backward; built from torch's own operations the sum made about eight such tensors a step
    (the product, the clamp, the exponentials, their masks and gradients). The one difference
    from autograd: below the cut, where a lobe is held at e⁻⁶⁰, its slope is taken as
    w_k κ_k e⁻⁶⁰ (under 1e-23) instead of 0.

    Args (of ``apply``):
        cosine: (m, n) n·h ≤ 1.
        weights: (K,) w_k ≥ 0, or (m, K): pixel p's own.
        sharpness: (K,) κ_k, constant.

    Returns:
        (m, n) the lobes' sum.
    """

    @staticmethod
    def forward(ctx, cosine: torch.Tensor, weights: torch.Tensor, sharpness: torch.Tensor) -> torch.Tensor:
        lobes = torch.mul(sharpness[:, None, None], cosine - 1).clamp_(min=MIN_EXPONENT).exp_()
        ctx.save_for_backward(lobes, weights, sharpness)
        if weights.dim() == 1:
            return torch.tensordot(weights, lobes, 1)
        total = torch.zeros_like(cosine)
        for k, lobe in enumerate(lobes):
            total.addcmul_(weights[:, k, None], lobe)
        return total

    @staticmethod
    def backward(ctx, grad: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, None]:
        lobes, weights, sharpness = ctx.saved_tensors
        if weights.dim() == 1:
            flat = lobes.reshape(len(weights), -1)
            d_cosine = ((weights * sharpness) @ flat).view_as(grad).mul_(grad)
            return d_cosine, flat @ grad.reshape(-1), None
        d_cosine = torch.zeros_like(grad)
        for k, lobe in enumerate(lobes):
            d_cosine.addcmul_((weights[:, k] * sharpness[k])[:, None], lobe)
        return d_cosine.mul_(grad), torch.einsum("kmn,mn->mk", lobes, grad), None


class DepthPyramid(nn.Module):
    """A depth map as a start plus corrections at ``levels`` scales (full, ½, ¼, …), each
    upsampled bilinearly: gradient steps move the coarse shape as fast as the fine detail.

    Args:
        start: (H, W) depth to start from.
        levels: number of scales.
    """

    def __init__(self, start: torch.Tensor, levels: int = 4):
        super().__init__()
        self.register_buffer("start", start.float())
        h, w = start.shape
        self.corrections = nn.ParameterList(
            nn.Parameter(torch.zeros(1, 1, max(1, h >> k), max(1, w >> k))) for k in range(levels))

    def forward(self) -> torch.Tensor:
        """(H, W) depth."""
        depth = self.start
        for k, correction in enumerate(self.corrections):
            up = F.interpolate(correction, size=depth.shape, mode="bilinear", align_corners=False)
            depth = depth + up[0, 0] * 2 ** k
        return depth


class SelfCalibrationModel(nn.Module):
    """Lights (directions, intensities and colours), depth, albedo and specular lobes of one
    subject on its working grid.

    Args:
        scaled_lights: (n, 3) s̃_i, the first guess (direction × relative intensity).
        depth: (H, W) starting depth; mask: (H, W) bool with m object pixels.
        albedo: (m, 3) starting RGB albedo (> 0).
        sharpness: the lobes' κ_k.
        materials: (m,) each pixel's material j, 0 … J − 1, each with its own lobe weights;
            None: one material.
        lobes: (J, K) starting lobe weights w_jk > 0; None: every one e⁻⁵ (nearly off).
    """

    def __init__(self, scaled_lights: torch.Tensor, depth: torch.Tensor, mask: torch.Tensor,
                 albedo: torch.Tensor, sharpness: tuple[float, ...], levels: int = 4,
                 materials: torch.Tensor | None = None, lobes: torch.Tensor | None = None):
        super().__init__()
        self.register_buffer("scaled_lights", scaled_lights.float())
        self.register_buffer("mask", mask)
        self.register_buffer("sharpness", torch.tensor(sharpness, dtype=torch.float32))
        self.register_buffer("view", torch.tensor(VIEW))
        self.depth = DepthPyramid(depth, levels)
        self.columns = nn.Parameter(torch.eye(3)[:, :2].clone())          # c_x, c_y
        self.gbr = nn.Parameter(torch.tensor([0.0, 0.0, 1.0]))            # μ, ν, λ
        self.light_residual = nn.Parameter(torch.zeros_like(self.scaled_lights))
        self.log_albedo = nn.Parameter(albedo.clamp_min(1e-6).log())
        if materials is None:
            materials = torch.zeros(len(albedo), dtype=torch.long)
        self.register_buffer("materials", materials.long())
        count = int(materials.max()) + 1 if len(materials) else 1
        logits = torch.full((count, len(sharpness)), -5.0) if lobes is None else \
            torch.special.expm1(lobes.double()).log().float()          # softplus⁻¹
        self.lobe_logits = nn.Parameter(logits)
        self.log_tint = nn.Parameter(torch.zeros_like(self.scaled_lights))

    def frame(self) -> torch.Tensor:
        """(3, 3) A = [c_x | c_y | μ c_x + ν c_y + λ e_z], scaled to determinant ±1."""
        mu, nu, lam = self.gbr
        third = mu * self.columns[:, 0] + nu * self.columns[:, 1] + lam * self.view
        a = torch.cat([self.columns, third[:, None]], 1)
        return a / torch.det(a).abs().pow(1 / 3)

    def lights(self) -> tuple[torch.Tensor, torch.Tensor]:
        """(n, 3) unit directions and (n,) intensities with geometric mean 1."""
        scaled = (self.scaled_lights + self.light_residual) @ self.frame()
        length = scaled.norm(dim=-1)
        return scaled / length[:, None], (length.log() - length.log().mean()).exp()

    def tints(self) -> torch.Tensor:
        """(n, 3) each light's colour relative to the first guess's: geometric mean 1 over each
        light's channels and over each channel's lights (the object's own colour is the
        albedo's)."""
        centred = self.log_tint - self.log_tint.mean(1, keepdim=True)
        return (centred - centred.mean(0, keepdim=True)).exp()

    def normals(self) -> torch.Tensor:
        """(m, 3) unit normals of the current depth."""
        return normals_from_depth(self.depth(), self.mask)

    def lobes(self) -> torch.Tensor:
        """(J, K) the lobes' weights w_jk ≥ 0 of each of the J materials."""
        return F.softplus(self.lobe_logits)

    @torch.no_grad()
    def visibility(self) -> torch.Tensor:
        """(m, n) V: 0 where the current depth hides pixel p from the current light i (marched
        one sample per pixel of the grid's diagonal, :func:`unps.geometry.cast_shadows`), else 1."""
        directions, _ = self.lights()
        steps = math.ceil(math.hypot(*self.mask.shape))
        hidden = cast_shadows(self.depth().float(), self.mask, directions.float(), 1.0, steps)
        return (~hidden[:, self.mask]).T.float().contiguous()

    def forward(self, visible: torch.Tensor | None = None) -> torch.Tensor:
        """(m, n, 3) the rendered images at the object pixels, cast shadows where ``visible``
        (m, n) is 0 (None: every light reaches every pixel)."""
        lit, specular = self.lit_and_lobes(visible)
        return lit * (self.log_albedo.exp()[:, None, :] + specular[..., None])

    @torch.no_grad()
    def highlight_share(self) -> float:
        """The share of the rendered light (summed over the pixels, images and channels; no cast
        shadows) that the specular lobes put there, the rest being the albedo's: about 0 for a
        matte surface."""
        lit, specular = self.lit_and_lobes()
        highlights = (lit * specular[..., None]).sum()
        diffuse = (lit * self.log_albedo.exp()[:, None, :]).sum()
        return float(highlights / (highlights + diffuse).clamp_min(1e-12))

    def lit_and_lobes(self, visible: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """(m, n, 3) the light reaching each pixel, its colour and n·l (0 in cast shadows, where
        ``visible`` (m, n) is 0), and (m, n) the sum of its material's specular lobes there: the
        rendering is their product with albedo + lobes."""
        directions, intensities = self.lights()
        normals = self.normals()
        shading = (normals @ directions.T).clamp_min(0)                                    # (m, n)
        halfway = F.normalize(directions + self.view, dim=-1)
        cosine = (normals @ halfway.T).clamp(max=1)
        lobes = self.lobes()
        weights = lobes[0] if len(lobes) == 1 else lobes[self.materials]
        specular = SpecularLobes.apply(cosine, weights, self.sharpness)
        if visible is not None:
            shading = shading * visible
        return (intensities[:, None] * self.tints())[None] * shading[..., None], specular

"""The explicit image model that self-calibration fits: a surface, its reflectance and the lights.

Every pixel p of the working grid under image i is rendered as

    X̃_ip = V_ip · e_i · max(n_p·l_i, 0) · (ρ_p + Σ_k w_jk · exp(κ_k (n_p·h_i − 1))),  j = j(p)

with V_ip 0 where the depth map casts a shadow on p from light i and 1 elsewhere
(:meth:`SelfCalibrationModel.visibility`), n_p the normal of a depth map (so the normals are
integrable), ρ_p an RGB diffuse albedo,
w_jk ≥ 0 the weights of K spherical-Gaussian specular lobes of fixed sharpness κ_k, shared by the
pixels of one material j (the object's pixels are split into a few materials by colour before the
fit, :func:`unps.lights.selfcal.material_labels`), h_i the half vector between l_i and the view
v = (0, 0, 1) (orthographic), and (l_i, e_i) the direction and intensity of light i. With
interreflections on, each pixel adds a · ρ_p · Σ_q K_pq B_qi, one bounce of the diffuse light B_qi =
V_iq e_i max(n_q·l_i, 0) ρ_q the other parts of the surface send it, through Nayar's kernel K
(:func:`facet_kernel`) of the current depth, and a a fitted scale that turns the albedo into a
reflectance (the images' exposure is unknown).

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
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from unps.geometry import cast_shadows
from unps.solvers.nayar import interreflection_kernel

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


@dataclass(frozen=True)
class FacetKernel:
    """Nayar's interreflection kernel between blocks (facets) of the working grid.

    Attributes:
        index: (m,) the facet of each object pixel, 0 … f − 1.
        counts: (f,) object pixels per facet.
        kernel: (f, f) K_ij (:func:`unps.solvers.nayar.interreflection_kernel`): the light facet
            i receives from facet j per unit of j's radiance.
    """

    index: torch.Tensor
    counts: torch.Tensor
    kernel: torch.Tensor

    def to(self, device: torch.device) -> FacetKernel:
        return FacetKernel(self.index.to(device), self.counts.to(device), self.kernel.to(device))

    def received(self, radiance: torch.Tensor) -> torch.Tensor:
        """(m, n, 3) the light each pixel receives from the other facets, Σ_j K_ij B_j, with B_j
        the facet's mean of ``radiance`` (m, n, 3): what one bounce adds, times its albedo."""
        pooled = torch.zeros(len(self.counts), *radiance.shape[1:], dtype=radiance.dtype,
                             device=radiance.device).index_add_(0, self.index, radiance)
        pooled = pooled / self.counts[:, None, None]
        return (self.kernel @ pooled.flatten(1)).view_as(pooled)[self.index]


def facet_kernel(depth: torch.Tensor, mask: torch.Tensor, normals: torch.Tensor,
                 max_facets: int) -> FacetKernel:
    """The interreflection kernel of a depth map on blocks of s × s pixels, s the least that
    leaves at most ``max_facets`` blocks with an object pixel (the kernel is O(f²)).

    Args:
        depth: (H, W) in pixels of the grid; mask: (H, W) bool with m object pixels.
        normals: (m, 3) unit normals at the object pixels (row-major).
    """
    rows, cols = (i.cpu().numpy() for i in torch.nonzero(mask.cpu(), as_tuple=True))
    side = max(1, math.ceil(math.sqrt(len(rows) / max_facets)))
    while True:
        width = -(-mask.shape[1] // side)
        flat = rows // side * width + cols // side
        if len(np.unique(flat)) <= max_facets:
            break
        side += 1
    occupied, index = np.unique(flat, return_inverse=True)
    counts = np.bincount(index).astype(np.float64)
    height = -(-mask.shape[0] // side)
    on = np.zeros(height * width, bool)
    on[occupied] = True
    on = on.reshape(height, width)
    facet_depth = np.zeros((height, width))
    facet_depth[on] = np.bincount(index, depth.detach().cpu().double().numpy()[rows, cols]) / counts / side
    summed = np.stack([np.bincount(index, c) for c in normals.detach().cpu().double().numpy().T], -1)
    facet_normals = np.zeros((height, width, 3))
    facet_normals[on] = summed / np.maximum(np.linalg.norm(summed, axis=-1, keepdims=True), 1e-12)
    kernel = interreflection_kernel(facet_depth, facet_normals, on)
    return FacetKernel(torch.as_tensor(index), torch.as_tensor(counts, dtype=torch.float32),
                       torch.as_tensor(kernel, dtype=torch.float32))


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
        max_facets: render one bounce of diffuse interreflection too, on blocks of the grid, at
            most this many (:func:`facet_kernel`): each pixel also reflects, with its albedo times
            a fitted scale a (0 < a < 2 / the start's 99th-percentile albedo, started at an
            eighth of that: a cavity's images raise it, a convex surface's leave it low), the
            diffuse light the other blocks send it, as :meth:`update_received` last found it;
            None: no interreflection.
    """

    def __init__(self, scaled_lights: torch.Tensor, depth: torch.Tensor, mask: torch.Tensor,
                 albedo: torch.Tensor, sharpness: tuple[float, ...], levels: int = 4,
                 materials: torch.Tensor | None = None, lobes: torch.Tensor | None = None,
                 max_facets: int | None = None):
        super().__init__()
        self.max_facets = max_facets
        self.receiving = False         # whether the last update found any light sent between facets
        self.register_buffer("received", torch.zeros(len(albedo) if max_facets else 0, len(scaled_lights), 3))
        self.register_buffer("bounce_limit", 2 / torch.quantile(albedo.mean(1), 0.99).clamp_min(1e-6))
        self.bounce_logit = nn.Parameter(torch.tensor(-2.0))
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
        (m, n) is 0 (None: every light reaches every pixel), plus one bounce of the light the
        other facets sent at the last :meth:`update_received`."""
        lit, specular = self.lit_and_lobes(visible)
        albedo = self.log_albedo.exp()[:, None, :]
        rendered = lit * (albedo + specular[..., None])
        if not self.receiving:         # none yet, or a convex surface: no facet sees another
            return rendered
        return rendered + self.bounce_scale() * albedo * self.received

    def bounce_scale(self) -> torch.Tensor:
        """() a: the albedo's share that is reflectance, for the light received from other facets."""
        return self.bounce_limit * torch.sigmoid(self.bounce_logit)

    @torch.no_grad()
    def update_received(self, visible: torch.Tensor | None = None) -> None:
        """Σ_j K_ij B_j at every pixel, the kernel made from the current depth and B the current
        diffuse radiance (cast shadows where ``visible`` (m, n) is 0): held until the next
        update. The kernel follows the depth: made once from the start's, which the images'
        interreflections leave shallower than the surface, it renders too little of them and
        the lights bend all the same."""
        if self.max_facets is None:
            return
        kernel = facet_kernel(self.depth(), self.mask, self.normals(), self.max_facets)
        lit, _ = self.lit_and_lobes(visible)
        self.received.copy_(kernel.to(self.received.device).received(lit * self.log_albedo.exp()[:, None, :]))
        self.receiving = bool(kernel.kernel.any())

    @torch.no_grad()
    def bounce_share(self) -> float:
        """The share of the rendered light (no cast shadows) that the last :meth:`update_received`
        adds by interreflection: 0 without it, about 0 on a convex surface."""
        if not self.receiving:
            return 0.0
        rendered = self()
        bounced = self.bounce_scale() * self.log_albedo.exp()[:, None, :] * self.received
        return float(bounced.sum() / rendered.sum().clamp_min(1e-12))

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

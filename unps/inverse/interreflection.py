"""ξ_n2: Nayar's interreflections inside the renderer (supplementary Eqs. 2–3, §2.2 (b)).

The facets F (rows ρ_j·n_j: the robust initialisation's albedo times the network's normals
N_o) become the pseudo facets that interreflection makes the camera see,

    F_ny = (I − P K)⁻¹ F,

with P = diag(ρ) and K Nayar's kernel between facets (:func:`unps.solvers.nayar.interreflection_kernel`:
K_ij = V_ij · max(n_i·d, 0) · max(n_j·(−d), 0) / (π|d|⁴) · A_j with d = x_j − x_i, V_ij the
visibility of the segment between facets i and j over the depth map and A_j = 1/n_j,z the
facet's area, so K is zero between facets that face away from each other). N_ny are the rows of
F_ny normalised. K lives on a grid ``downsample`` times coarser (the kernel is O(m²)); the
correction F_ny − F is smooth, so it is upsampled and added to the full-resolution ρ·N_o, which
keeps the normals' detail. K depends on depth, which comes from the normals by Eq. 1: it is
rebuilt and (I − P K) LU-factorised only when :meth:`Interreflection.update` is called (every
100 steps), and each step only solves with the factors, a differentiable O(m²) operation.

Frame: x right, y up, z toward the camera; tensors (1, 3, H, W).
"""

from __future__ import annotations

import logging

import numpy as np
import torch
import torch.nn.functional as F

from unps.grid import block_mean
from unps.errors import InputError
from unps.geometry import integrate_normals
from unps.solvers.nayar import interreflection_kernel, kernel_on_device

log = logging.getLogger(__name__)


class Interreflection:
    """The facet grid, P, and the current factorisation of (I − P K).

    Args:
        mask: (H, W) bool, the working grid's object pixels.
        albedo: (H, W) gray albedo ρ (robust initialisation), as a reflectance
            (:func:`unps.solvers.nayar.reflectance_scale`).
        downsample: facet grid factor.
        occlusion: include visibility in K.
    """

    def __init__(self, mask: np.ndarray, albedo: np.ndarray, downsample: int = 4,
                 occlusion: bool = True):
        if int(downsample) != downsample or downsample < 1:
            raise InputError(f"interreflection.downsample must be a whole number >= 1, got {downsample}")
        self.mask, self.factor, self.occlusion = mask, int(downsample), occlusion
        facet_albedo, self.facets = block_mean(albedo[..., None], mask, self.factor)
        if not self.facets.any():
            raise InputError(f"no facet is at least half on the object at interreflection.downsample="
                             f"{downsample}: the object is too small for that factor")
        self.albedo_full = torch.as_tensor(albedo, dtype=torch.float32)
        self.albedo = torch.as_tensor(facet_albedo[self.facets, 0], dtype=torch.float32)
        self.index = torch.as_tensor(np.flatnonzero(self.facets))
        self.lu: torch.Tensor | None = None            # float64, on the update's device
        self.pivots: torch.Tensor | None = None
        self._cache: dict = {}                         # the same, per (device, dtype) in use

    @property
    def n_facets(self) -> int:
        return int(self.index.numel())

    def facet_normals(self, normals: np.ndarray) -> np.ndarray:
        """(H, W, 3) unit normals → (h, w, 3) unit facet normals (mask-weighted block means)."""
        mean, _ = block_mean(normals, self.mask, self.factor)
        return mean / np.maximum(np.linalg.norm(mean, axis=-1, keepdims=True), 1e-12)

    def update(self, normals: np.ndarray, device: torch.device = torch.device("cpu")) -> None:
        """Depth (Eq. 1) on the facet grid, K from it and the normals, and factorise (I − P K).

        On a GPU the kernel, its visibility (the O(m²) part) and the factorisation are computed
        there (:func:`unps.solvers.nayar.kernel_on_device`); the depth of the facet grid, a
        sparse solve over m unknowns, stays on the CPU.

        Args:
            normals: (H, W, 3) unit normals on the working grid.
            device: where the factors are computed and kept.
        """
        coarse = self.facet_normals(normals)
        depth = integrate_normals(coarse, self.facets)
        if device.type == "cpu":
            kernel = torch.as_tensor(interreflection_kernel(depth, coarse, self.facets, self.occlusion))
        else:
            on = dict(device=device, dtype=torch.float64)
            kernel = kernel_on_device(torch.as_tensor(depth, **on), torch.as_tensor(coarse, **on),
                                      torch.as_tensor(self.facets, device=device), self.occlusion)
        a = torch.eye(len(kernel), dtype=torch.float64, device=device) \
            - self.albedo.to(device, torch.float64)[:, None] * kernel
        self.lu, self.pivots = torch.linalg.lu_factor(a)
        self._cache = {}
        log.debug("interreflection kernel: %d facets, mean row sum %.3f", len(kernel),
                  float(kernel.sum(1).mean()))

    def __call__(self, normals: torch.Tensor) -> torch.Tensor:
        """N_ny from N_o (differentiable in N_o).

        Args:
            normals: (1, 3, H, W) unit normals N_o.

        Returns:
            (1, 3, H, W) unit pseudo normals N_ny.
        """
        if self.lu is None:
            raise RuntimeError("Interreflection.update must be called before the first solve")
        on = self._on(normals.device, normals.dtype)
        scaled = normals * on["albedo"]                                    # ρ·N_o, full grid
        facets = self._pool(scaled, on)                                    # (m, 3) F
        solved = torch.linalg.lu_solve(on["lu"], on["pivots"], facets)     # (m, 3) F_ny
        correction = self._upsample(solved - facets, normals.shape[-2:], on)
        return F.normalize(scaled + correction, dim=1, eps=1e-12)

    def _on(self, device: torch.device, dtype: torch.dtype) -> dict[str, torch.Tensor]:
        """The factors and the grids a solve reads, on ``device`` (in ``dtype``; the indices as
        they are), made once per update: copied at every step, each copy would hold a GPU's queue."""
        key = (device, dtype)
        if key not in self._cache:
            grid = lambda array: torch.as_tensor(array, device=device, dtype=dtype)[None, None]   # noqa: E731
            self._cache[key] = {"lu": self.lu.to(device, dtype), "pivots": self.pivots.to(device),
                                "albedo": self.albedo_full.to(device, dtype), "mask": grid(self.mask),
                                "facets": grid(self.facets), "index": self.index.to(device)}
        return self._cache[key]

    def _pool(self, values: torch.Tensor, on: dict[str, torch.Tensor]) -> torch.Tensor:
        """(1, 3, H, W) → (m, 3): mask-weighted means over each facet's block (``on``: :meth:`_on`)."""
        f = self.factor
        h, w = values.shape[-2:]
        pad = (0, -w % f, 0, -h % f)
        weight = on["mask"]
        total = F.avg_pool2d(F.pad(weight, pad), f)
        summed = F.avg_pool2d(F.pad(values * weight, pad), f)
        means = summed / total.clamp_min(1e-12)
        return means.flatten(2)[0, :, on["index"]].T

    def _upsample(self, values: torch.Tensor, shape, on: dict[str, torch.Tensor]) -> torch.Tensor:
        """(m, 3) facet values → (1, 3, H, W), bilinear and normalised by the facet mask so
        that the edges are not pulled toward zero (as :func:`unps.solvers.nayar.upsample`)."""
        hf, wf = self.facets.shape
        grid = torch.zeros(3, hf * wf, device=values.device, dtype=values.dtype)
        grid[:, on["index"]] = values.T
        size = (hf * self.factor, wf * self.factor)
        spread = F.interpolate(grid.view(1, 3, hf, wf), size=size, mode="bilinear", align_corners=False)
        cover = F.interpolate(on["facets"], size=size, mode="bilinear", align_corners=False)
        out = spread / cover.clamp_min(1e-6)
        return out[..., : shape[0], : shape[1]]

"""The inverse-rendering networks (supplementary §2.2, after Taniai & Maehara 2018).

``NormalNet`` is the estimation branch ξ_f, ξ_n1: every image and the mask in, unit normals N_o
and global features out. ``ReflectanceNet`` is f_sp: per image, the (noisy) image and its
specular-reflectance map together with the global features in, a non-negative RGB reflectance
map out. Both are plain convolutional networks over the whole image grid.

Frame: x right, y up, z toward the camera; tensors are (B, C, H, W) with row 0 at the top.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

def init_gaussian(module: nn.Module, std: float = 0.02) -> None:
    """Draw every conv weight from N(0, std²) and zero the biases (the paper's initialisation;
    its "0.02 variance" is read as DCGAN's customary standard deviation 0.02)."""
    for m in module.modules():
        if isinstance(m, nn.Conv2d):
            nn.init.normal_(m.weight, 0.0, std)
            if m.bias is not None:
                nn.init.zeros_(m.bias)


def _conv(cin: int, cout: int, kernel: int) -> nn.Conv2d:
    """Zero padding: the grid is a crop with black background around the object, and zeros
    continue it (replicate padding cost a fifth of each CPU step for nothing the fit uses)."""
    return nn.Conv2d(cin, cout, kernel, padding=kernel // 2)


def _norm(channels: int, batch_norm: bool) -> nn.Module:
    """Batch normalisation over the current batch's pixels, never running averages (Taniai &
    Maehara's: the same statistics in the fit and the read-out), or nothing."""
    return nn.BatchNorm2d(channels, track_running_stats=False) if batch_norm else nn.Identity()


def normal_net_input(images: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """(n, 3, H, W) images and (H, W) mask → (1, 3n + 1, H, W), :class:`NormalNet`'s input.

    It is the same at every step, so it is built once, channels-last (the layout the CPU's
    convolutions run fastest in).
    """
    stacked = torch.cat([images.flatten(0, 1), mask.to(images.dtype)[None]])[None]
    return stacked.contiguous(memory_format=torch.channels_last)


class NormalNet(nn.Module):
    """ξ_f (feature extractor) and ξ_n1 (normal head) over all images at once.

    Input: the n images stacked as 3n channels plus the mask; ``depth`` − 1 convolutions of
    ``width`` channels with leaky ReLU (ξ_f), then one to 3 channels normalised to unit length
    (ξ_n1). With width 384, depth 4 and 96 images this is Taniai & Maehara's normal network and
    the paper's ≈ 3.7 M parameters.

    Args:
        n_images: n.
        width: channels of ξ_f.
        depth: convolutions in total (ξ_f and ξ_n1).
        first_kernel: kernel size of the first convolution (3 as the paper; 1 is 9× cheaper
            on the 3n-channel input).
        batch_norm: normalise each of ξ_f's layers over the grid (Taniai & Maehara's code).
    """

    def __init__(self, n_images: int, width: int = 384, depth: int = 4, first_kernel: int = 3,
                 batch_norm: bool = False):
        super().__init__()
        layers: list[nn.Module] = [_conv(3 * n_images + 1, width, first_kernel), _norm(width, batch_norm),
                                   nn.LeakyReLU(0.1)]
        for _ in range(depth - 2):
            layers += [_conv(width, width, 3), _norm(width, batch_norm), nn.LeakyReLU(0.1)]
        self.features = nn.Sequential(*layers)
        self.head = _conv(width, 3, 3)
        init_gaussian(self)

    def forward(self, inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """
        Args:
            inputs: (1, 3n + 1, H, W), the normalised images and the mask
                (:func:`normal_net_input`).

        Returns:
            normals (1, 3, H, W) unit, and features (1, width, H, W).
        """
        features = self.features(inputs)
        return F.normalize(self.head(features).float(), dim=1, eps=1e-8), features


class ReflectanceNet(nn.Module):
    """f_sp: one reflectance map per image from the image, its specular map and the global
    features.

    The first layer acts on [image ‖ specular map ‖ global features]; since a convolution is
    linear, its global-feature part is computed once per step and shared by every image
    (:meth:`global_term`) instead of being repeated n times: the same network, n times cheaper.

    Args:
        feature_width: channels of the global features (NormalNet's width).
        width: channels of f_sp (16 in Taniai & Maehara).
        depth: convolutions after the global features join, the first layer's included.
        branch: convolutions on [image ‖ specular map] alone, up to the first layer's (1: the
            image meets the global features at once; Taniai & Maehara's code has 5).
        batch_norm: normalise each hidden layer over the batch's images and pixels.
        feature_scale: factor on the global features' term of the first layer (1: as Taniai &
            Maehara). Under Adam each weight moves by about the learning rate a step, so that term
            grows with ``feature_width``: a 384-wide normal network's features outweigh the image
            in f_sp from the first steps unless scaled down (:meth:`Preset.feature_scale
            <unps.inverse.settings.Preset.feature_scale>`).
    """

    def __init__(self, feature_width: int, width: int = 16, depth: int = 3, batch_norm: bool = False,
                 branch: int = 1, feature_scale: float = 1.0):
        super().__init__()
        self.feature_scale = feature_scale
        own: list[nn.Module] = []
        for k in range(branch - 1):
            own += [_conv(4 if k == 0 else width, width, 3), _norm(width, batch_norm), nn.LeakyReLU(0.1)]
        self.image_branch = nn.Sequential(*own)
        self.image_in = _conv(4 if branch == 1 else width, width, 3)
        self.feature_in = nn.Conv2d(feature_width, width, 3, padding=1, bias=False)
        self.in_norm = _norm(width, batch_norm)
        layers: list[nn.Module] = []
        for _ in range(depth - 2):
            layers += [_conv(width, width, 3), _norm(width, batch_norm), nn.LeakyReLU(0.1)]
        self.body = nn.Sequential(*layers)
        self.out = _conv(width, 3, 3)
        init_gaussian(self)

    def global_term(self, features: torch.Tensor) -> torch.Tensor:
        """(1, F, H, W) global features → (1, width, H, W), the first layer's shared part."""
        shared = self.feature_in(features)
        return shared if self.feature_scale == 1 else shared * self.feature_scale

    def forward(self, images: torch.Tensor, specular: torch.Tensor, shared: torch.Tensor) -> torch.Tensor:
        """
        Args:
            images: (B, 3, H, W) the images to explain (noise already added).
            specular: (B, 1, H, W) specular-reflectance maps R_i.
            shared: (1, width, H, W) from :meth:`global_term`.

        Returns:
            (B, 3, H, W) reflectance ≥ 0 (softplus).
        """
        own = self.image_in(self.image_branch(torch.cat([images, specular], 1)))
        x = F.leaky_relu(self.in_norm(own + shared), 0.1)
        return F.softplus(self.out(self.body(x)).float())


def specular_map(normals: torch.Tensor, lights: torch.Tensor) -> torch.Tensor:
    """Specular-reflectance maps R_i = vᵀ(2(n·l_i)n − l_i), v = (0, 0, 1) (supplementary Eqs. 9–10).

    R_i is the cosine between the view direction and the mirror reflection of l_i about n:
    1 where a highlight would be brightest.

    Args:
        normals: (1, 3, H, W) unit normals, unps frame.
        lights: (B, 3) unit surface-to-light directions.

    Returns:
        (B, 1, H, W), 2·n_z·(n·l_i) − l_z,i.

    Example:
        >>> n = torch.tensor([0.0, 0.6, 0.8]).view(1, 3, 1, 1)
        >>> specular_map(n, torch.tensor([[0.0, 0.0, 1.0]])).item()   # 2·0.8·0.8 − 1
        0.28...
    """
    if normals.ndim != 4 or normals.shape[:2] != (1, 3):
        raise ValueError(f"normals must be (1, 3, H, W), got {tuple(normals.shape)}")
    if lights.ndim != 2 or lights.shape[1] != 3:
        raise ValueError(f"lights must be (B, 3), got {tuple(lights.shape)}")
    n_dot_l = torch.einsum("chw,bc->bhw", normals[0], lights)
    return (2 * normals[0, 2] * n_dot_l - lights[:, 2, None, None])[:, None]


def shading(normals: torch.Tensor, lights: torch.Tensor) -> torch.Tensor:
    """Attached-shadow Lambertian shading max(n·l_i, 0).

    Args:
        normals: (1, 3, H, W) unit; lights: (B, 3) unit, surface to light.

    Returns:
        (B, 1, H, W).
    """
    return torch.einsum("chw,bc->bhw", normals[0], lights).clamp_min(0)[:, None]

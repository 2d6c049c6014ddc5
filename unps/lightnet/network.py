"""The light estimation network (supplementary §2.1, Fig. 3; LCNet of SDPS-Net).

All images of one object go through one shared feature extractor; their features are fused
by a max over the images (any number of them); a classifier sees each image's own features
next to the fused ones and predicts that image's light as azimuth, elevation and intensity bins.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from unps.errors import InputError
from unps.lightnet.bins import ANGLE_BINS, INTENSITY_BINS


def conv(cin: int, cout: int, stride: int) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(cin, cout, 3, stride, 1), nn.LeakyReLU(0.1, inplace=True))


def channels_last(x: torch.Tensor) -> torch.Tensor:
    """(N, C, H, W) stored channels-last: oneDNN's fast layout for these convolutions on a CPU
    (1.4× per training step, ``experiments/light_estimation/throughput.py``)."""
    return x.contiguous(memory_format=torch.channels_last)


def normalise_stack(images: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Divide each stack by its mean over the object, so only relative brightness remains.

    Intensities are known only up to one scale per object (albedo × light), so the network
    sees, and predicts, brightness relative to its stack.

    Args:
        images: (B, n, 3, H, W); mask: (B, 1, H, W).
    """
    weight = mask.unsqueeze(1)
    mean = (images * weight).sum((1, 2, 3, 4)) / (weight.sum((1, 2, 3, 4)) * images.shape[1] * 3)
    return images / mean.clamp_min(1e-8).view(-1, 1, 1, 1, 1)


LCNET_STRIDES = (2, 2, 1, 2, 1, 2, 1)
"""LCNet's extractor: it halves the resolution in its first two layers, then every other one."""
LATE_STRIDES = (2, 1, 2, 1, 2, 1, 2)
"""Halving in every other layer from the first: the same layers at twice LCNet's resolution
from the second on, so 1.8× the operations (``recipe=cpu``'s, and the shipped weights')."""


class LightNet(nn.Module):
    """Per-image light directions and intensities from a stack of images of one object.

    Args:
        width: channels of the first layer; the extractor is width·(1, 2, 2, 2, 2, 4, 4)
            (64 gives the paper's 64-128-128-128-128-256-256).
        head_width: hidden units of each classification head.
        strides: of the extractor's seven layers; four 2s, so that it halves the resolution
            four times (:data:`LCNET_STRIDES`, :data:`LATE_STRIDES`).
    """

    def __init__(self, width: int = 64, head_width: int = 64,
                 strides: tuple[int, ...] = LCNET_STRIDES):
        super().__init__()
        if sorted(strides) != [1, 1, 1, 2, 2, 2, 2]:
            raise InputError(f"light.strides: seven, four of them 2 and three 1, got {list(strides)}")
        c = width
        channels = [4, c, 2 * c, 2 * c, 2 * c, 2 * c, 4 * c, 4 * c]
        self.extractor = nn.Sequential(*(conv(cin, cout, stride) for cin, cout, stride in
                                         zip(channels[:-1], channels[1:], strides)))
        self.classifier = nn.Sequential(conv(8 * c, 4 * c, 1), conv(4 * c, 4 * c, 2),
                                        conv(4 * c, 4 * c, 1))
        self.embed = nn.Sequential(nn.Linear(4 * c * 16, 4 * c), nn.LeakyReLU(0.1, inplace=True))
        self.heads = nn.ModuleDict({
            name: nn.Sequential(nn.Linear(4 * c, head_width), nn.LeakyReLU(0.1, inplace=True),
                                nn.Linear(head_width, bins))
            for name, bins in (("azimuth", ANGLE_BINS), ("elevation", ANGLE_BINS),
                               ("intensity", INTENSITY_BINS))})

    def forward(self, images: torch.Tensor, mask: torch.Tensor) -> dict[str, torch.Tensor]:
        """
        Args:
            images: (B, n, 3, H, W) linear images, any scale; H = W, a multiple of 32
                (128 for the paper).
            mask: (B, 1, H, W) object mask.

        Returns:
            logits ``azimuth`` (B, n, 36), ``elevation`` (B, n, 36), ``intensity`` (B, n, 20).
        """
        b, n, _, h, w = images.shape
        x = torch.cat([normalise_stack(images, mask),
                       mask.unsqueeze(1).expand(b, n, 1, h, w)], 2).flatten(0, 1)
        features = self.extractor(channels_last(x))                    # (B·n, 4c, h/16, w/16)
        own = features.unflatten(0, (b, n))
        fused = own.max(1, keepdim=True).values.expand_as(own)
        x = self.classifier(channels_last(torch.cat([own, fused], 2).flatten(0, 1)))
        x = self.embed(F.adaptive_avg_pool2d(x, 4).flatten(1))
        return {name: head(x).unflatten(0, (b, n)) for name, head in self.heads.items()}

"""What holds self-calibrated lights near the light network's estimate (:mod:`unps.lights.selfcal`).

Images pin some of what they show of the lights far better than the rest: a rotation of all the
lights together changes every pixel, a bas-relief of a matte object or one light of twelve hardly
any, and a model that cannot render everything the images hold (several glosses, cast shadows it
misplaces, interreflections, 8-bit floors) bends the lights it is free to bend. So the fit pays

    weight · mean_i [ θ_i² / (σ₀² + s_i²) + (log e_i)² / σ_e² ]

for light i's direction θ_i away from the first guess (s_i the spread of the network's passes for
that light, σ₀ a floor) and its intensity e_i away from the first guess's (the images are divided
by those, so the first guess is e_i = 1). Letting a rotation of the whole set go cheaper, as the
images seem to pin it, was measured and not kept: on the light benchmark it gained more where it
helped and lost far more where the model could not render the object
(``experiments/light_benchmark/README.md``).

Frame: x right, y up, z toward the camera; directions unit, surface to light.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from unps.data.lights import Lights


@dataclass(frozen=True)
class NetworkPrior:
    """The pull toward the first guess.

    Attributes:
        directions: (n, 3) the first guess's unit directions.
        weights: (n,) 1 / (σ₀² + s_i²), rad⁻².
        weight: the pull's weight against the mean absolute image error.
        intensity_sigma: σ_e.
    """

    directions: torch.Tensor
    weights: torch.Tensor
    weight: float
    intensity_sigma: float

    def to(self, device: torch.device) -> NetworkPrior:
        """The same prior with its tensors on ``device``."""
        return NetworkPrior(self.directions.to(device), self.weights.to(device), self.weight,
                            self.intensity_sigma)

    def cost(self, directions: torch.Tensor, intensities: torch.Tensor) -> torch.Tensor:
        """The pull on (n, 3) unit ``directions`` and (n,) ``intensities`` (geometric mean 1),
        differentiable in both.

        >>> prior = NetworkPrior(torch.tensor([[0.0, 0.0, 1.0]]), torch.tensor([1.0]), 1.0, 0.1)
        >>> tilted = torch.tensor([[math.sin(0.1), 0.0, math.cos(0.1)]])
        >>> round(prior.cost(tilted, torch.ones(1)).item(), 4)     # θ² for θ = 0.1 rad
        0.01
        """
        squared = 2 * (1 - (directions * self.directions).sum(-1))                 # ≈ θ²
        return self.weight * ((self.weights * squared).mean()
                              + intensities.log().pow(2).mean() / self.intensity_sigma ** 2)


def network_prior(lights: Lights, weight: float, floor_deg: float,
                  intensity_sigma: float) -> NetworkPrior | None:
    """The pull toward ``lights`` (their ``spread_deg`` loosens it light by light); None when
    ``weight`` is 0."""
    if weight <= 0:
        return None
    spread = lights.spread_deg if lights.spread_deg is not None else np.zeros(len(lights.directions))
    variance = math.radians(floor_deg) ** 2 + np.radians(spread.astype(np.float64)) ** 2
    return NetworkPrior(torch.as_tensor(lights.directions, dtype=torch.float32),
                        torch.as_tensor(1 / variance, dtype=torch.float32), weight, intensity_sigma)

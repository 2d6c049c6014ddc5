"""Why the light network fails on the concave subjects: interreflections, or shape?

    python experiments/light_estimation/concave_failures.py [--checkpoint PATH] [--spp 16]
        [--subjects Vase BrokenPot Rose] [--as-configured]

Each subject is rendered twice with the same samples per pixel: with direct light only (path
length 2: attached and cast shadows, no interreflection) and as the benchmark renders it (path
length 5: interreflections). The network's one-pass direction MAE on both bounds what modelling
interreflections in its training data can gain: if it is as wrong without them, the failure lies
elsewhere. Then the structure of the error on the standard render: the rotation that best maps
the true directions onto the estimates (its angle and what remains after it: a half-turn leaves
little), and the linear map that does (a bas-relief-like distortion leaves little after it but
not after a rotation), and the mean zenith angle of the true and the estimated lights (an
elevation bias, the bas-relief ambiguity's mark on nearly flat subjects). ``--as-configured``
skips the direct-only render and scores the subject's configured (cached) render.
"""

from __future__ import annotations

import argparse

import numpy as np
import torch
from hydra import compose, initialize_config_module
from hydra.utils import instantiate

from unps.lightnet.estimate import network_estimate
from unps.lights.contour import best_rotation, rotation_angle
from unps.metrics import light_direction_mae


def render(name: str, max_depth: int | None = None, spp: int | None = None):
    """The subject's configured render, or one with another path length and sample count."""
    overrides = [f"subject={name}"]
    if max_depth is not None:
        overrides += [f"subject.render.max_depth={max_depth}", f"subject.render.spp={spp}"]
    with initialize_config_module("unps.conf", version_base=None):
        spec = compose("fit", overrides=overrides).subject
    return instantiate(spec, _partial_=True)()


def best_linear(truth: np.ndarray, estimate: np.ndarray) -> np.ndarray:
    """(3, 3) A, up to scale, that best makes A·tᵢ parallel to eᵢ: the unit A minimising
    Σ‖eᵢ × A·tᵢ‖² (the direct linear transform), with the sign that points A·tᵢ along eᵢ."""
    skew = np.zeros((len(truth), 3, 3))
    skew[:, [2, 0, 1], [1, 2, 0]] = estimate
    skew[:, [1, 2, 0], [2, 0, 1]] = -estimate                  # skew[i] @ v = eᵢ × v
    design = (skew[:, :, :, None] * truth[:, None, None, :]).reshape(-1, 9)   # column 3j+k: A[j, k]
    matrix = np.linalg.svd(design)[2][-1].reshape(3, 3)
    return matrix if np.einsum("ij,ij->", truth @ matrix.T, estimate) > 0 else -matrix


def mapped_error(matrix: np.ndarray, truth: np.ndarray, estimate: np.ndarray) -> float:
    """Direction MAE (degrees) between the estimates and the true directions mapped by ``matrix``."""
    mapped = truth @ matrix.T
    return light_direction_mae(mapped / np.linalg.norm(mapped, axis=1, keepdims=True), estimate)


def mean_zenith(directions: np.ndarray) -> float:
    """Mean angle (degrees) of (n, 3) unit directions from the view axis."""
    return float(np.degrees(np.arccos(np.clip(directions[:, 2], -1, 1))).mean())


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--checkpoint", help="default: the weights shipped with unps")
    parser.add_argument("--spp", type=int, default=16, help="samples per pixel of both renders")
    parser.add_argument("--subjects", nargs="+", default=["Vase", "BrokenPot", "Rose"])
    parser.add_argument("--as-configured", action="store_true",
                        help="only the subject's configured render, no direct-only one")
    args = parser.parse_args()
    torch.set_num_threads(1)

    spp = "as configured" if args.as_configured else f"{args.spp} spp"
    print(f"one-pass direction MAE, {spp:<13}  direct only   interreflections   │   "
          "best rotation   after it   after best linear map   │   zenith: true   estimated")
    for name in args.subjects:
        errors = {}
        for max_depth in (5,) if args.as_configured else (2, 5):
            subject = render(name) if args.as_configured else render(name, max_depth, args.spp)
            estimate = network_estimate(subject, args.checkpoint, soft_decode=True).directions
            errors[max_depth] = light_direction_mae(estimate, subject.light_directions)
        truth = subject.light_directions.astype(np.float64)
        estimate = estimate.astype(np.float64)
        rotation = best_rotation(truth, estimate)
        direct = f"{errors[2]:9.2f}°" if 2 in errors else f"{'—':>10}"
        print(f"{name:<36} {direct}   {errors[5]:13.2f}°     │   {rotation_angle(rotation):11.1f}°  "
              f"{mapped_error(rotation, truth, estimate):8.2f}°   "
              f"{mapped_error(best_linear(truth, estimate), truth, estimate):14.2f}°          │   "
              f"{mean_zenith(truth):10.1f}°  {mean_zenith(estimate):9.1f}°", flush=True)


if __name__ == "__main__":
    main()

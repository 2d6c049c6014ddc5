"""Is the light network's softmax calibrated? Temperature scaling on held-out stacks of its own mix.

    python experiments/light_estimation/temperature.py                 # 512 stacks, ~5 min on 2 cores
    python experiments/light_estimation/temperature.py --samples 128 --checkpoint PATH

The network classifies each light's azimuth, elevation and relative intensity into bins and
``light=estimated`` reads them by soft-arg-max, the mean of the softmax: a softmax sharper or
broader than the network's real uncertainty moves that mean. Temperature scaling (Guo et al.,
ICML 2017) divides the logits by one number T chosen to minimise the negative log-likelihood of
the true bins on held-out data. Here the held-out data are stacks of the training mix itself
(``unps/conf/train.yaml``'s ``data`` and the weights' recipe, a seed no run trained or validated
on), never the light benchmark or DiLiGenT, which then judge the chosen T
(``../light_benchmark/decoding.py``).

Prints, per head and temperature, the mean NLL of the true bin and, for the angles, the direction
MAE of one pass decoded at that temperature; the NLL-optimal T of each head is marked *.
"""

from __future__ import annotations

import argparse

import numpy as np
import torch
from hydra import compose, initialize_config_module

from unps.lightnet.bins import ANGLE_RANGE, angles_to_direction, decode, encode_lights
from unps.lightnet.data import LightData
from unps.lightnet.system import load_lightnet
from unps.metrics import light_direction_mae

TEMPERATURES = (0.7, 0.85, 1.0, 1.15, 1.3, 1.5, 1.75, 2.0, 2.5)
HELD_OUT_SEED = 31_337   # no training run or validation set has used it (their seeds are 0-7 and
                         # those plus LightData's VALIDATION_SEED_OFFSET)


def held_out(samples: int, recipe: dict) -> torch.utils.data.Dataset:
    """``samples`` stacks of the training mix (``train.yaml``'s ``data``) at the weights' own
    resolution and image count."""
    with initialize_config_module("unps.conf", version_base=None):
        cfg = compose("train", overrides=[f"recipe.resolution={recipe['resolution']}",
                                          f"recipe.images={recipe['images']}",
                                          f"recipe.val_samples={samples}"])
    data = LightData(cfg.recipe, cfg.data, HELD_OUT_SEED)
    data.setup("fit")
    return data.val_set


@torch.no_grad()
def collect(net, dataset, batch: int = 8) -> tuple[dict, dict, torch.Tensor]:
    """Every stack's logits per head (N·n, bins), their true bins (N·n,) and true directions (N·n, 3)."""
    logits, targets, directions = {}, {}, []
    for start in range(0, len(dataset), batch):
        items = torch.utils.data.default_collate(
            [dataset[i] for i in range(start, min(start + batch, len(dataset)))])
        out = net(items["images"], items["mask"])
        truth = dict(zip(("azimuth", "elevation", "intensity"),
                         encode_lights(items["directions"], items["intensities"])))
        for head in truth:
            logits.setdefault(head, []).append(out[head].reshape(-1, out[head].shape[-1]))
            targets.setdefault(head, []).append(truth[head].reshape(-1))
        directions.append(items["directions"].reshape(-1, 3))
    return ({h: torch.cat(v) for h, v in logits.items()}, {h: torch.cat(v) for h, v in targets.items()},
            torch.cat(directions))


def nll(logits: torch.Tensor, target: torch.Tensor, temperature: float) -> float:
    """Mean negative log-likelihood of the true bins under softmax(logits / T)."""
    return float(torch.nn.functional.cross_entropy(logits / temperature, target))


def direction_mae(logits: dict, truth: torch.Tensor, temperature: float) -> float:
    """Direction MAE of one pass (no symmetries) read by soft-arg-max at temperature T."""
    seen = angles_to_direction(decode(logits["azimuth"] / temperature, *ANGLE_RANGE, soft=True),
                               decode(logits["elevation"] / temperature, *ANGLE_RANGE, soft=True))
    return light_direction_mae(seen.numpy(), truth.numpy())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--checkpoint", default=None, help="weights (default: the shipped ones)")
    parser.add_argument("--samples", type=int, default=512)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    net, config = load_lightnet(args.checkpoint)
    dataset = held_out(args.samples, config["recipe"])
    logits, targets, directions = collect(net, dataset)
    print(f"{args.samples} held-out stacks of the training mix, {config['recipe']['images']} images, "
          f"{config['recipe']['resolution']} px, seed {HELD_OUT_SEED}")
    print(f"{'T':>6}" + "".join(f"{h + ' NLL':>16}" for h in logits) + f"{'direction MAE':>16}")
    table = {h: [nll(logits[h], targets[h], t) for t in TEMPERATURES] for h in logits}
    best = {h: int(np.argmin(v)) for h, v in table.items()}
    for k, t in enumerate(TEMPERATURES):
        print(f"{t:>6.2f}"
              + "".join(f"{table[h][k]:>15.4f}{'*' if best[h] == k else ' '}" for h in logits)
              + f"{direction_mae(logits, directions, t):>15.2f}°")


if __name__ == "__main__":
    main()

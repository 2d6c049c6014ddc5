"""How should the light network's bins be read? Soft-arg-max at several temperatures, the mean unit
vector, arg-max, and with the training's prior over the bins divided out.

    python experiments/light_benchmark/decoding.py               # benchmark, single, DiLiGenT, unps's renders
    python experiments/light_benchmark/decoding.py --only diligent --sets 12
    python experiments/light_benchmark/decoding.py --report      # the table from what has run

The network classifies each light's azimuth and elevation into 36 bins of 5° over [−90°, 90°]
(:mod:`unps.lightnet.bins`); ``light=estimated`` reads them by soft-arg-max, the mean of the
softmax. Where the softmax is broad its mean moves with its shape, and a softmax sharper or broader than the
network's real uncertainty moves it; a temperature t divides the logits before the softmax (t < 1
sharpens it). ``temperature.py`` in ``../light_estimation/`` asks which t the network's own
held-out stacks call calibrated; this asks which reading wins on captures it has never seen.

Per case: the network's eight passes (as ``light=estimated`` runs them), their logits kept once and
read under each of :data:`DECODINGS`; the direction error, slant bias and intensity error of each
reading. None of it feeds training. Results are kept case by case in ``--out`` (default
``<cache>/decoding``); a rerun resumes.
"""

from __future__ import annotations

import functools
import sys
from pathlib import Path

import numpy as np
import torch

from unps.lightnet.bins import (ANGLE_BINS, ANGLE_RANGE, INTENSITY_RANGE, angles_to_direction, bin_centres,
                               decode, direction_to_angles, to_bin)
from unps.lightnet.estimate import FRAMINGS, network_input, paired, pass_logits
from unps.lightnet.rig import draw_lights
from unps.lightnet.symmetry import SYMMETRIES, mean_direction
from unps.lightnet.system import load_lightnet
from unps.metrics import light_direction_mae, light_intensity_error, light_slant_bias

sys.path.insert(0, str(Path(__file__).resolve().parent))
import benchmark  # noqa: E402
import runs  # noqa: E402

DECODINGS = ("soft", "T0.8", "T1.25", "T1.5", "T2", "vector", "vectorT1.5", "argmax", "prior", "prior0.5")
"""``soft``: the shipped soft-arg-max of each angle; ``T<t>``: softmax(logits / t) first;
``vector``: the mean unit vector (:func:`expected_direction`), ``vectorT<t>``
at temperature t; ``argmax``: the top bins' centres; ``prior``: the softmax divided by the
training mix's share of lights in each bin first (:func:`training_prior`), ``prior<w>`` by that
share to the power w."""

PRIOR_FLOOR = 0.01   # bins the training mix hardly reaches are divided by this share of the fullest


def expected_direction(azimuth_logits: torch.Tensor, elevation_logits: torch.Tensor) -> torch.Tensor:
    """(..., 36) azimuth and elevation logits → (..., 3) unit directions: the mean of the unit
    vectors of every pair of bin centres under the two softmaxes (taken as independent),
    normalised. Unlike the soft-arg-max of each angle, it weighs a bin by where its direction
    lies on the sphere, not on the angle's axis.

    Example:
        >>> logits = torch.full((36,), -1e9); logits[[17, 18]] = 0.0   # ±2.5°, equally likely
        >>> expected_direction(logits, logits).round(decimals=6).abs()
        tensor([0., 0., 1.])
    """
    centres = bin_centres(azimuth_logits.shape[-1], *ANGLE_RANGE, azimuth_logits.device)
    centres = centres.to(azimuth_logits.dtype)
    p_az, p_el = torch.softmax(azimuth_logits, -1), torch.softmax(elevation_logits, -1)
    sin_az, cos_az = (p_az * centres.sin()).sum(-1), (p_az * centres.cos()).sum(-1)
    sin_el, cos_el = (p_el * centres.sin()).sum(-1), (p_el * centres.cos()).sum(-1)
    return torch.nn.functional.normalize(torch.stack([cos_el * sin_az, sin_el, cos_el * cos_az], -1), dim=-1)


@functools.cache
def training_prior(draws: int = 4000, seed: int = 0) -> torch.Tensor:
    """(36,) log share of the training mix's light directions in each angle bin: its rig layouts
    (``unps/conf/train.yaml``) drawn ``draws`` times, azimuth and elevation pooled (every layout
    is drawn at a random turn about the view axis, so the two share one distribution); each share
    at least :data:`PRIOR_FLOOR` of the fullest bin's. Dividing the softmax by it reads the
    network's answer as if every bin were as likely a priori (a correction for label shift,
    Saerens et al., Neural Computation 2002)."""
    from hydra import compose, initialize_config_module

    with initialize_config_module("unps.conf", version_base=None):
        data = compose("train").data
    generator = torch.Generator().manual_seed(seed)
    layouts = dict(data.layouts)
    lights = torch.cat([draw_lights(layouts, data.lights_per_shape, data.max_zenith_deg, generator)
                        for _ in range(draws)])
    angles = torch.cat(direction_to_angles(lights))
    share = torch.bincount(to_bin(angles, ANGLE_BINS, *ANGLE_RANGE), minlength=ANGLE_BINS).double()
    share = share.clamp_min(PRIOR_FLOOR * share.max())
    return torch.log(share / share.sum()).float()


def read_directions(logits: dict, how: str) -> torch.Tensor:
    """(n, 3) unit directions from one pass's (n, 36) angle logits, read as ``how`` (:data:`DECODINGS`)."""
    az, el = logits["azimuth"], logits["elevation"]
    if how.startswith("prior"):
        log_prior = float(how.removeprefix("prior") or 1) * training_prior()
        az, el = az - log_prior, el - log_prior
        how = "soft"
    name, _, temperature = how.partition("T")
    if temperature:
        az, el = az / float(temperature), el / float(temperature)
    if name == "vector":
        return expected_direction(az, el)
    soft = name != "argmax"
    return angles_to_direction(decode(az, *ANGLE_RANGE, soft), decode(el, *ANGLE_RANGE, soft))


@torch.no_grad()
def passes_logits(subject, net, resolution: int) -> list[tuple[dict, torch.Tensor]]:
    """The logits of ``light=estimated``'s eight passes, each with its frame matrix M."""
    observed = subject.observed_images()
    inputs = {fill: network_input(observed, subject.mask, resolution, fill) for fill in FRAMINGS}
    out = []
    for fill, frame in paired(FRAMINGS, SYMMETRIES):
        logits, matrix = pass_logits(net, *inputs[fill], *frame)
        out.append(({k: v[0] for k, v in logits.items()}, matrix))
    return out


def run_case(subject, net, resolution: int) -> dict:
    """Direction error, slant bias and intensity error of the eight passes' mean under each decoding."""
    passes = passes_logits(subject, net, resolution)
    truth = subject.light_directions
    intensities = torch.stack([decode(lg["intensity"], *INTENSITY_RANGE, soft=True) for lg, _ in passes])
    intensities = (intensities / intensities.mean(1, keepdim=True)).mean(0).numpy()
    result = {"intensity": light_intensity_error(intensities, subject.light_intensities.mean(1))}
    for how in DECODINGS:
        seen = [read_directions(lg, how) @ m for lg, m in passes]
        directions = mean_direction(torch.stack(seen))[0].numpy()
        result[how] = {"error": light_direction_mae(directions, truth),
                       "slant": light_slant_bias(directions, truth)}
    return result


def report(rows: dict) -> str:
    """Per group and light set: the mean direction error under each decoding (the lowest marked
    *), then the median slant bias under each."""
    head = f"{'group':<13} {'set':>4} {'cases':>5}  " + "".join(f"{h:>11}" for h in DECODINGS)
    blocks = []
    for key, title in (("error", "mean direction error"), ("slant", "median slant bias")):
        lines = [title, head]
        for group, label, chosen in runs.by_light_set(rows):
            values = [[r[h][key] for h in DECODINGS] for r in chosen]
            summary = np.mean(values, 0) if key == "error" else np.median(values, 0)
            best = int(np.argmin(summary)) if key == "error" else -1
            lines.append(f"{group:<13} {label:>4} {len(chosen):>5}  " + "".join(
                f"{v:>10.2f}{'*' if k == best else '°'}" for k, v in enumerate(summary)))
        blocks.append("\n".join(lines))
    return "\n\n".join(blocks)


def progress(case: tuple, row: dict, result: dict) -> str:
    return f"{' '.join(case)}: " + " ".join(f"{h} {row[h]['error']:.2f}°" for h in DECODINGS)


def main() -> None:
    parser = benchmark.study_parser(__doc__.split("\n")[0], "default: <cache>/decoding",
                                    groups=("benchmark", "single", "diligent", "synthetic"))
    args = parser.parse_args()
    cases = benchmark.study_cases(args)
    out = args.out or args.cache / "decoding"
    try:
        runs.claim(out, {"study": "decoding", "decodings": list(DECODINGS),
                         "weights": runs.weights_digest(None),
                         **benchmark.capture_options(args)})
    except ValueError as e:
        parser.error(str(e))
    net, config = load_lightnet(None)
    resolution = config["recipe"]["resolution"]
    print(report(runs.summaries(cases, out, lambda subject: run_case(subject, net, resolution),
                                lambda r: r, progress, args.report)))


if __name__ == "__main__":
    main()

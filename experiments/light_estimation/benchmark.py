"""The light network: real DiLiGenT, held-out synthetic renders per BRDF family, and speed.

    python experiments/light_estimation/benchmark.py [--checkpoint PATH] [--data ../shared/data]
    python experiments/light_estimation/benchmark.py --only diligent --renders Face Tablet1 Vase

1. DiLiGenT (ball 16-bit, cat and pot1 crops, all 96 images): direction MAE of the lights as
   the network gives them in one pass, averaged over the eight symmetries of the square
   (``light.symmetric=true light.framings=[1.0]``) and as ``light=estimated`` averages them by
   default (its ``symmetric`` and ``framings``); of the default, the median spread of its
   passes, its scale-invariant intensity error, its direction MAE after the cast-shadow reversal
   test (``light.reversal=shadows``, the default) and then also aligned to the occluding contour
   (``light.align=contour``), and the normal MAE of the robust initialisation with those lights,
   the aligned ones and the ground-truth ones.
   Then the default's direction MAE on random subsets of 16, 12 and 8 of the 96 images (sparse
   rigs). With ``--renders Face Tablet1 …``, the same directions for unps's own rendered subjects.
2. Held-out synthetic stacks (seeds never used in training) of the checkpoint's own recipe, per
   BRDF family: analytic and measured-span lobes always, MERL neural fits when
   ``<data>/merl_nbrdf`` exists, MERL tables with ``--merl-dir``; and per shape family (blob,
   vessel, relief, sculpture), seen through the simulated camera under every light layout; then
   every shape family of one material against the same of two laid on in patches; each row also
   after the cast-shadow reversal test.
3. Framings (``light.framings``): held-out stacks per shape family rendered at twice the network's
   resolution and framed as ``light=estimated`` frames a capture (cropped to the object, then
   area-resized), the direction MAE of one pass, of the eight symmetries, of the default's eight
   passes (symmetries and framings in turn) and of all 32 pairs of symmetry and framing.
4. Speed of the checkpoint's recipe on this machine: generating one batch (one core, as the
   training's data worker) against one training step.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import torch
from omegaconf import OmegaConf

from unps.data.diligent import read_diligent_object
from unps.data.subject import Subject
from unps.errors import InputError
from unps.lights import Lights, light_errors, with_lights
from unps.lightnet.bins import decode_lights, encode_lights
from unps.lightnet.estimate import FRAMINGS, network_input, network_lights, network_pass, paired
from unps.lightnet.materials import MaterialBank
from unps.lightnet.rig import LAYOUTS, Camera
from unps.lightnet.shapes import SHAPES
from unps.lightnet.symmetry import SYMMETRIES, mean_direction
from unps.lightnet.synthesis import LightDataset
from unps.lightnet.system import SHIPPED, batch_light_errors, build_net, load_lightnet
from unps.metrics import light_direction_mae, normal_metrics
from unps.lights.contour import ContourAlignment
from unps.lights.reversal import ReversalTest
from unps.solvers.rpca import robust_init

DEFAULT_DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
OBJECTS = ("ball", "cat", "pot1")


def diligent(data: Path, checkpoint, quantization: str = "auto"):
    """``quantization``: ``auto`` reads the 8-bit crops as ``floor``, the way they were made."""
    print("DiLiGenT, all 96 images   1-pass dir MAE   8-sym dir MAE   default dir MAE   spread   int err   "
          "reversal-tested   aligned dir MAE   RPCA(est) °  RPCA(aligned) °  RPCA(GT) °")
    for name in OBJECTS:
        try:
            subject = read_diligent_object(data / "DiLiGenT", name, quantization=quantization)
        except InputError as e:
            print(f"{name:<6} skipped: {e}")
            continue
        one_pass, averaged, lights = passes(subject, checkpoint)
        tested, _ = ReversalTest()(subject, lights)
        aligned, _ = ContourAlignment()(subject, tested)
        errors = light_errors(lights, subject)
        est = robust_init(with_lights(subject, tested), tested.directions)
        est_aligned = robust_init(with_lights(subject, aligned), aligned.directions)
        gt = robust_init(subject, subject.light_directions)
        mae = lambda e: normal_metrics(e.normals, subject.normals, subject.mask)["normal_mae"]  # noqa: E731
        print(f"{name:<25} {light_errors(one_pass, subject)['light_dir_mae']:>15.2f}° "
              f"{light_errors(averaged, subject)['light_dir_mae']:>14.2f}° "
              f"{errors['light_dir_mae']:>16.2f}° {np.median(lights.spread_deg):>7.1f}° "
              f"{errors['light_int_err']:>9.3f} "
              f"{light_errors(tested, subject)['light_dir_mae']:>16.2f}° "
              f"{light_errors(aligned, subject)['light_dir_mae']:>16.2f}° {mae(est):>12.2f} "
              f"{mae(est_aligned):>16.2f} {mae(gt):>11.2f}", flush=True)



def passes(subject: Subject, checkpoint) -> tuple[Lights, Lights, Lights]:
    """The network's lights in one pass, averaged over the eight symmetries, and averaged as
    ``light=estimated`` does by default; none reversal-tested or aligned."""
    network = lambda **how: network_lights(subject, checkpoint, **how)[0]  # noqa: E731
    return (network(symmetric=False, framings=[1.0]), network(symmetric=True, framings=[1.0]),
            network())


def sparse(data: Path, checkpoint, counts=(16, 12, 8), draws: int = 5):
    """Direction MAE of the default estimate on random subsets of DiLiGenT's 96 images (mean ± sd over draws):
    sparse light sets like small rigs', the network seeing only those images."""
    print(f"DiLiGenT, random subsets ({draws} draws each)   " +
          "   ".join(f"{count:>2} images" for count in counts))
    rng = np.random.default_rng(0)
    for name in OBJECTS:
        try:
            subject = read_diligent_object(data / "DiLiGenT", name, quantization="auto")
        except InputError as e:
            print(f"{name:<6} skipped: {e}")
            continue
        cells = []
        for count in counts:
            errors = []
            for _ in range(draws):
                subset = subject.select(np.sort(rng.choice(subject.n_images, count, replace=False)))
                lights, _ = network_lights(subset, checkpoint)
                errors.append(light_errors(lights, subset)["light_dir_mae"])
            cells.append(f"{np.mean(errors):5.2f} ± {np.std(errors):4.2f}°")
        print(f"{name:<42} " + "   ".join(cells), flush=True)

def renders(names: list[str], checkpoint):
    """Direction MAE as the network gives it and aligned, on unps's rendered subjects (cached)."""
    from hydra import compose, initialize_config_module
    from hydra.utils import instantiate

    print("rendered subject          1-pass dir MAE   8-sym dir MAE   default dir MAE   spread   "
          "reversal-tested   aligned dir MAE")
    with initialize_config_module("unps.conf", version_base=None):
        for name in names:
            subject = instantiate(compose("fit", overrides=[f"subject={name}"]).subject, _partial_=True)()
            one_pass, averaged, lights = passes(subject, checkpoint)
            tested, _ = ReversalTest()(subject, lights)
            aligned, _ = ContourAlignment()(subject, tested)
            print(f"{name:<25} {light_errors(one_pass, subject)['light_dir_mae']:>15.2f}° "
                  f"{light_errors(averaged, subject)['light_dir_mae']:>14.2f}° "
                  f"{light_errors(lights, subject)['light_dir_mae']:>16.2f}° "
                  f"{np.median(lights.spread_deg):>7.1f}° "
                  f"{light_errors(tested, subject)['light_dir_mae']:>16.2f}° "
                  f"{light_errors(aligned, subject)['light_dir_mae']:>16.2f}°", flush=True)


@torch.no_grad()
def synthetic(net, config, families: dict, samples: int):
    """Held-out stacks per BRDF family (blobs, the cap of lights, no camera), per shape family
    (analytic materials, every light layout, the simulated camera), and every shape of one
    material against the same of two (analytic and measured-span, laid on in patches)."""
    recipe = config["recipe"]
    common = dict(resolution=recipe["resolution"], images=recipe["images"], seed=987_654)
    print(f"held-out synthetic ({recipe['resolution']} px, {recipe['images']} images, {samples} "
          f"stacks per family)   dir MAE   int err   reversal-tested")
    for family, bank in families.items():
        score(net, LightDataset(samples, materials=bank, family=family, **common), f"BRDF {family}")
    for shape in SHAPES:
        score(net, LightDataset(samples, shape=shape, layouts=dict.fromkeys(LAYOUTS, 1.0),
                                camera=Camera(), **common), f"shape {shape} (rig layouts, camera)")
    mixed = dict(shapes=dict.fromkeys(SHAPES, 1.0), layouts=dict.fromkeys(LAYOUTS, 1.0), camera=Camera(),
                 materials=MaterialBank(analytic=1, measured=1), **common)
    for share, label in ((0.0, "one material"), (1.0, "two materials in patches")):
        score(net, LightDataset(samples, second_material=share, **mixed),
              f"every shape, {label} (rig layouts, camera)")


def score(net, ds: LightDataset, label: str) -> None:
    """Direction MAE and intensity error of the network, and the direction MAE after the
    cast-shadow reversal test (:class:`unps.lights.reversal.ReversalTest`)."""
    maes, errs, tested = [], [], []
    for i in range(0, len(ds), 8):
        batch = torch.utils.data.default_collate([ds[j] for j in range(i, min(i + 8, len(ds)))])
        logits = net(batch["images"], batch["mask"])
        d, e = decode_lights(logits["azimuth"], logits["elevation"], logits["intensity"], True)
        mae, err = batch_light_errors(d, e, batch["directions"], batch["intensities"])
        maes.append(mae), errs.append(err)
        for images, mask, directions, intensities, truth in zip(
                batch["images"], batch["mask"], d, e, batch["directions"]):
            subject = Subject("held-out", images.permute(0, 2, 3, 1).numpy(), mask[0].numpy() > 0.5)
            lights = Lights(directions.numpy(), intensities[:, None].repeat(1, 3).numpy(), "estimated")
            tested.append(light_direction_mae(ReversalTest()(subject, lights)[0].directions, truth.numpy()))
    print(f"{label:<60} {torch.cat(maes).mean():>7.2f}° {torch.cat(errs).mean():>9.3f} "
          f"{np.mean(tested):>16.2f}°", flush=True)


@torch.no_grad()
def framed(net, config, samples: int) -> None:
    """Part 3: every pair of symmetry and framing once per stack, then each way of averaging them."""
    recipe = config["recipe"]
    resolution = recipe["resolution"]
    pairs = [(fill, frame) for fill in FRAMINGS for frame in SYMMETRIES]
    schemes = {"1 pass": [(1.0, SYMMETRIES[0])], "8 symmetries": [(1.0, f) for f in SYMMETRIES],
               "default (8 passes)": paired(FRAMINGS, SYMMETRIES), "all 32 pairs": pairs}
    print(f"framed held-out stacks (rendered at {2 * resolution} px, {recipe['images']} images, "
          f"{samples} per family; framings {', '.join(f'{f:g}' for f in FRAMINGS)})\n{'dir MAE':<40}" +
          "".join(f"{name:>20}" for name in schemes))
    totals = {name: [] for name in schemes}
    for shape in SHAPES:
        ds = LightDataset(samples, resolution=2 * resolution, images=recipe["images"], seed=987_654,
                          shape=shape, layouts=dict.fromkeys(LAYOUTS, 1.0), camera=Camera())
        errors = {name: [] for name in schemes}
        for item in map(ds.__getitem__, range(len(ds))):
            images, mask = item["images"].permute(0, 2, 3, 1).numpy(), item["mask"][0].numpy() > 0.5
            inputs = {fill: network_input(images, mask, resolution, fill) for fill in FRAMINGS}
            estimates = {(fill, frame): network_pass(net, *inputs[fill], *frame)[0] for fill, frame in pairs}
            for name, chosen in schemes.items():
                mean = mean_direction(torch.stack([estimates[p] for p in chosen]))[0]
                errors[name].append(light_direction_mae(mean.numpy(), item["directions"].numpy()))
        for name, values in errors.items():
            totals[name].append(np.mean(values))
        print(f"shape {shape:<34}" + "".join(f"{np.mean(v):>19.2f}°" for v in errors.values()), flush=True)
    print(f"{'mean over the families but relief':<40}" +
          "".join(f"{np.mean([v for s, v in zip(SHAPES, t) if s != 'relief']):>19.2f}°"
                  for t in totals.values()))


def speed(config, steps: int = 10):
    recipe = config["recipe"]
    ds = LightDataset(steps * recipe["batch_size"], resolution=recipe["resolution"],
                      images=recipe["images"])
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    start = time.perf_counter()
    batches = [torch.utils.data.default_collate([ds[i * recipe["batch_size"] + j]
                                                 for j in range(recipe["batch_size"])])
               for i in range(steps)]
    data_time = (time.perf_counter() - start) / steps
    torch.set_num_threads(recipe.get("threads") or threads)
    net = build_net(config)
    optimizer = torch.optim.Adam(net.parameters(), 5e-4)
    start = time.perf_counter()
    for batch in batches:
        logits = net(batch["images"], batch["mask"])
        targets = encode_lights(batch["directions"], batch["intensities"])
        loss = sum(torch.nn.functional.cross_entropy(logits[k].flatten(0, 1), t.flatten())
                   for k, t in zip(("azimuth", "elevation", "intensity"), targets))
        optimizer.zero_grad(), loss.backward(), optimizer.step()
    step_time = (time.perf_counter() - start) / steps
    print(f"speed ({recipe['resolution']} px, {recipe['images']} images, batch "
          f"{recipe['batch_size']}, width {config['light']['width']}): data {data_time:.3f} s "
          f"per batch on one core, training step {step_time:.3f} s on {torch.get_num_threads()} threads")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--checkpoint", help="default: the weights shipped with unps")
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--merl-dir", type=Path, help="a folder of MERL .binary files")
    parser.add_argument("--samples", type=int, default=64)
    parser.add_argument("--quantization", choices=["auto", "round"], default="auto",
                        help="how to read DiLiGenT (round: the crops as read before unps read them as made)")
    parser.add_argument("--only", choices=["diligent", "synthetic", "framings", "speed"],
                        help="one part only")
    parser.add_argument("--framed-samples", type=int, default=32,
                        help="stacks per family in part 3 (32 passes each)")
    parser.add_argument("--renders", nargs="*", default=[], metavar="SUBJECT",
                        help="rendered subjects to add to the DiLiGenT part, e.g. Face Tablet1")
    args = parser.parse_args()

    net, config = load_lightnet(args.checkpoint)
    notes = torch.load(args.checkpoint or SHIPPED, weights_only=False).get("notes")
    print(f"weights: {args.checkpoint or 'shipped'}; recipe: "
          f"{OmegaConf.to_yaml(OmegaConf.create(config['recipe'])).strip().replace(chr(10), ', ')}")
    if notes:
        print(f"trained: {notes}")
    if args.only in (None, "diligent"):
        diligent(args.data, args.checkpoint, args.quantization)
        sparse(args.data, args.checkpoint)
        renders(args.renders, args.checkpoint)
    if args.only in (None, "synthetic"):
        synthetic(net, config, families(args.data, args.merl_dir), args.samples)
    if args.only in (None, "framings"):
        framed(net, config, args.framed_samples)
    if args.only in (None, "speed"):
        speed(config)


def families(data: Path, merl_dir: Path | None) -> dict:
    """The BRDF families to hold out: analytic, lobes spanning MERL's, and the MERL ones whose
    data is present."""
    banks = {"analytic": MaterialBank(), "measured": MaterialBank(analytic=0, measured=1)}
    if (data / "merl_nbrdf").is_dir():
        banks["neural"] = MaterialBank(analytic=0, neural_dir=str(data / "merl_nbrdf"), neural=1,
                                        exclude=frozenset())
    if merl_dir:
        banks["merl"] = MaterialBank(analytic=0, merl_dir=str(merl_dir), merl=1, exclude=frozenset())
    return banks


if __name__ == "__main__":
    main()

"""Self-calibrated lights (``light=selfcal``) against the network and the contour alignment.

    python experiments/self_calibration/benchmark.py                 # everything (~25 min, 2 cores)
    python experiments/self_calibration/benchmark.py --subjects ball cat pot1 --no-perturbation
    python experiments/self_calibration/benchmark.py --one-pass --framings 1 --align contour  # before 11-24
    python experiments/self_calibration/benchmark.py --shadows-every 0            # no cast shadows

1. Per subject (DiLiGenT ball, cat, pot1 read as made, all 96 images; unps's rendered subjects,
   rendered and cached on first use): light direction MAE of the network (averaged over the eight
   symmetries of the square unless --one-pass, and over the framings of ``light.framings``
   unless --framings), after the cast-shadow
   reversal test, after contour alignment and after self-calibration (the stages of
   ``light=selfcal``), the self-calibrated intensity error, the normal MAE of the robust
   initialisation with each of those lights and with the true ones, and the self-calibration's
   runtime on this machine.
2. The perturbation protocol of SCPS-NIR (Li & Li 2022, Table 2) on DiLiGenT: start from the true
   directions rotated by 10°, 20° and 40° about a random axis, or each moved by a random 10°,
   with unit intensities, and report where the self-calibration ends.
"""

from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from unps.data.catalogue import subjects
from unps.data.diligent import read_diligent_object
from unps.errors import InputError
from unps.lightnet.estimate import FRAMINGS, checked_framings, network_estimate
from unps.lights import Lights, light_errors, with_lights
from unps.lights.contour import ContourAlignment
from unps.lights.reversal import ReversalTest
from unps.lights.selfcal import SelfCalibration, self_calibrate
from unps.metrics import normal_metrics
from unps.solvers.rpca import robust_init

DEFAULT_DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
DILIGENT = ("ball", "cat", "pot1")
RENDERED = subjects("synthetic")


def load(name: str, data: Path):
    """A DiLiGenT development object or one of unps's rendered subjects."""
    if name in DILIGENT:
        return read_diligent_object(data / "DiLiGenT", name)
    from hydra import compose, initialize_config_module
    from hydra.errors import MissingConfigException
    from hydra.utils import instantiate

    with initialize_config_module("unps.conf", version_base=None):
        try:
            config = compose("fit", overrides=[f"subject={name}"])
        except MissingConfigException:
            raise InputError(f"no subject {name!r} (unps.conf/subject has none)") from None
        return instantiate(config.subject, _partial_=True)()


def available(names, data: Path):
    """(name, subject) for each subject that can be read; a line saying why for the others."""
    for name in names:
        try:
            yield name, load(name, data)
        except InputError as e:
            print(f"{name:<10} skipped: {e}")


def rpca_error(subject, lights: Lights) -> float:
    """Normal MAE (°) of the robust initialisation with these lights."""
    estimate = robust_init(with_lights(subject, lights), lights.directions)
    return normal_metrics(estimate.normals, subject.normals, subject.mask)["normal_mae"]


def compare(names, data: Path, settings: SelfCalibration, symmetric: bool = True,
            framings: tuple[float, ...] = FRAMINGS, align: bool = False) -> None:
    """One row per subject; ``symmetric``, ``framings`` and ``align`` as ``light.symmetric``,
    ``light.framings`` and ``light.align=contour`` (False: the contour column repeats the
    reversal's)."""
    print(f"{'subject':<10} {'network':>8} {'reversal':>8} {'contour':>8} {'selfcal':>8} {'int err':>8} │ "
          f"{'RPCA with: network':>19} {'contour':>8} {'selfcal':>8} {'GT':>6} │ {'time':>6}")
    for name, subject in available(names, data):
        truth = Lights(subject.light_directions, subject.light_intensities, "gt")
        network = network_estimate(subject, None, soft_decode=True, symmetric=symmetric,
                                   framings=framings)
        tested, _ = ReversalTest()(subject, network)
        contour = ContourAlignment()(subject, tested)[0] if align else tested
        start = time.perf_counter()
        selfcal, _ = self_calibrate(subject, contour, settings)
        runtime = time.perf_counter() - start
        stages = (network, contour, selfcal)
        directions = [light_errors(lights, subject)["light_dir_mae"] for lights in (network, tested,
                                                                                     contour, selfcal)]
        rpca = [rpca_error(subject, lights) for lights in (*stages, truth)]
        print(f"{name:<10} {directions[0]:>7.2f}° {directions[1]:>7.2f}° {directions[2]:>7.2f}° "
              f"{directions[3]:>7.2f}° "
              f"{light_errors(selfcal, subject)['light_int_err']:>8.3f} │ {rpca[0]:>18.2f}° "
              f"{rpca[1]:>7.2f}° {rpca[2]:>7.2f}° {rpca[3]:>5.2f}° │ {runtime:>5.0f}s", flush=True)


def perturbed(directions: np.ndarray, rotation: float, jitter: float, seed: int) -> np.ndarray:
    """(n, 3) directions rotated together by ``rotation`` degrees about a random axis, then each
    moved by ``jitter`` degrees about its own random axis perpendicular to it."""
    rng = np.random.default_rng(seed)
    axis = rng.normal(size=3)
    out = Rotation.from_rotvec(np.radians(rotation) * axis / np.linalg.norm(axis)).apply(directions)
    sideways = np.cross(out, rng.normal(size=out.shape))
    sideways /= np.linalg.norm(sideways, axis=1, keepdims=True)
    out = Rotation.from_rotvec(np.radians(jitter) * sideways).apply(out)
    return out.astype(np.float32)


def perturbation(names, data: Path, settings: SelfCalibration, seed: int) -> None:
    cases = ((10, 0), (20, 0), (40, 0), (0, 10))
    print(f"\nstarts perturbed from the true lights (seed {seed}): direction MAE start → end")
    print(f"{'subject':<10}" + "".join(f"{f'rot {r}° jitter {j}°':>22}" for r, j in cases))
    for name, subject in available(names, data):
        row = ""
        for rotation, jitter in cases:
            start = Lights(perturbed(subject.light_directions, rotation, jitter, seed), None, "perturbed")
            end, _ = self_calibrate(subject, start, settings)
            row += (f"{light_errors(start, subject)['light_dir_mae']:>13.2f}° → "
                    f"{light_errors(end, subject)['light_dir_mae']:>5.2f}°")
        print(f"{name:<10}{row}", flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--subjects", nargs="*", default=[*DILIGENT, *RENDERED])
    parser.add_argument("--perturb", nargs="*", default=list(DILIGENT),
                        help="subjects of the perturbation protocol")
    parser.add_argument("--no-perturbation", action="store_true")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--one-pass", action="store_true",
                        help="the network run once, not averaged over the symmetries (light.symmetric=false)")
    parser.add_argument("--framings", type=float, nargs="+", default=list(FRAMINGS),
                        help="as light.framings (1: the object filling the input, as before 2026-11-25)")
    parser.add_argument("--align", choices=("contour", "none"), default="none",
                        help="as light.align (none: null)")
    parser.add_argument("--shadows-every", type=int, default=SelfCalibration.shadows_every,
                        help="as light.selfcal.shadows_every (0: no cast shadows, as before 2026-11-25)")
    parser.add_argument("--verbose", action="store_true", help="the self-calibration's progress")
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(name)s: %(message)s")
    settings = SelfCalibration(shadows_every=args.shadows_every)
    try:
        framings = checked_framings(args.framings)
    except InputError as e:
        parser.error(str(e))
    compare(args.subjects, args.data, settings, not args.one_pass, framings, args.align == "contour")
    if not args.no_perturbation:
        perturbation(args.perturb, args.data, settings, args.seed)


if __name__ == "__main__":
    main()

"""How much of the final lights' error one common turn of the set explains, read off the traces.

    python experiments/light_benchmark/turn_share.py --only benchmark diligent synthetic

For each case traced by ``selfcal_steps.py`` (``--traces``, default the traces of today's
default, ``selfcal_steps-1000-lr0.02``), the final lights as the default decides
(``--limit``, ``--settle``) are carried onto the true ones by the best transform of the whole set
of each kind, and the mean direction error left is printed: a rotation; a shear
l → (l_x + a l_z, l_y + b l_z, l_z), the part of a turn about an axis in the image plane that a
bas-relief cannot make, which the images' integrability pins; and a generalised bas-relief
(l_z → μ l_x + ν l_y + λ l_z), which nothing Lambertian pins. The per group and light set means
follow. Cases whose lights no fit traced (the reversal test warned) are left out.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from scipy.optimize import minimize
from scipy.spatial.transform import Rotation

from unps.metrics import angular_error

sys.path.insert(0, str(Path(__file__).parent))
import benchmark  # noqa: E402
import scenes  # noqa: E402
import selfcal_steps  # noqa: E402


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def rotated(directions: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(n, 3) ``directions`` turned by the rotation vector ``x`` (radians)."""
    return directions @ Rotation.from_rotvec(x).as_matrix().T


def sheared(directions: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(n, 3) unit (l_x + a l_z, l_y + b l_z, l_z), ``x`` = (a, b)."""
    d = directions
    return _unit(np.stack([d[:, 0] + x[0] * d[:, 2], d[:, 1] + x[1] * d[:, 2], d[:, 2]], -1))


def bas_relief(directions: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(n, 3) unit (l_x, l_y, μ l_x + ν l_y + λ l_z), ``x`` = (μ, ν, log λ)."""
    d = directions
    return _unit(np.stack([d[:, 0], d[:, 1], x[0] * d[:, 0] + x[1] * d[:, 1] + np.exp(x[2]) * d[:, 2]], -1))


TRANSFORMS = {"rotation": (rotated, 3), "shear": (sheared, 2), "bas-relief": (bas_relief, 3)}


def left_after(directions: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    """The mean direction error (degrees) of ``directions`` (n, 3), as they are (``as is``) and
    after the best transform of each kind of :data:`TRANSFORMS` carries them onto ``truth``."""
    left = {"as is": float(angular_error(directions, truth).mean())}
    for name, (transform, size) in TRANSFORMS.items():
        best = minimize(lambda x: angular_error(transform(directions, x), truth).mean(), np.zeros(size),
                        method="Nelder-Mead", options={"xatol": 1e-7, "fatol": 1e-7, "maxiter": 4000})
        left[name] = float(best.fun)
    return left


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, default=benchmark.DEFAULT_DATA)
    parser.add_argument("--cache", type=Path, default=benchmark.DEFAULT_CACHE)
    parser.add_argument("--traces", type=Path, default=None,
                        help="selfcal_steps.py's folder (default <cache>/results/selfcal_steps-1000-lr0.02)")
    parser.add_argument("--only", nargs="+", choices=benchmark.GROUPS, default=list(benchmark.DEFAULT_GROUPS))
    parser.add_argument("--limit", type=selfcal_steps.limit_value, default=1.5,
                        help="light.selfcal.max_flattening_deg to read the traces under (default 1.5)")
    parser.add_argument("--settle", type=float, default=0.1, help="light.selfcal.settle_deg (default 0.1)")
    args = parser.parse_args(argv)
    traces = args.traces or args.cache / "results" / "selfcal_steps-1000-lr0.02"
    if not traces.is_dir():
        parser.error(f"--traces {traces}: no such folder (run selfcal_steps.py first)")
    stop = lambda fit: selfcal_steps.settled_step(fit, args.settle)   # noqa: E731
    rows: dict[tuple[str, str], list[dict]] = {}
    every_case = benchmark.cases(args.only, list(scenes.LIGHT_SETS), args.data, args.cache)
    for group, name, label, read in every_case:
        path = traces / f"{group}-{name}-{label}.json"
        if not path.exists():
            continue
        try:
            case = selfcal_steps.with_limit(json.loads(path.read_text()), args.limit)
        except ValueError as e:
            parser.error(f"--limit: {e}")
        directions = selfcal_steps.final_directions(case, stop)
        if directions is None:
            continue
        left = left_after(directions, read().light_directions.astype(np.float64))
        rows.setdefault((group, label), []).append(left)
        print(f"{group:<13}{name:<12}{label:>4}  " + "  ".join(f"{k} {v:6.2f}°" for k, v in left.items()),
              flush=True)
    print()
    for (group, label), cases in rows.items():
        means = {k: np.mean([c[k] for c in cases]) for k in cases[0]}
        shown = "  ".join(f"{k} {v:6.2f}°" for k, v in means.items())
        print(f"{group:<13}{label:>4} ({len(cases)} cases)  {shown}")


if __name__ == "__main__":
    main()

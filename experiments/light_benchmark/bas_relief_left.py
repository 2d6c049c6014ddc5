"""How much of the final lights' error is the bas-relief, and do interreflections pin it?
(Chandraker, Kahl & Kriegman, "Reflections on the generalized bas-relief ambiguity", CVPR 2005.)

    python experiments/light_benchmark/bas_relief_left.py --only benchmark diligent synthetic   # ~45 min
    python experiments/light_benchmark/bas_relief_left.py --report                              # the tables

Lambertian shading, attached and cast shadows are the same under lights S·P⁻¹ and scaled
normals B·Pᵀ for any generalised bas-relief P (μ, ν, λ: the surface z' = λz + μx + νy), so no
stage that reads them can tell the network's bas-relief from the truth's. Per case this runs the
light network alone and the default stages (``light=selfcal``) and fits, with the true lights,
the bas-relief P that brings each set nearest them (mean angle, Nelder–Mead from P = I): the
error *left* after it is what the stages could still fix without knowing P; the rest is P.

Interreflections are not invariant: one bounce between facets depends on the depth, and so on
λ. Under the final lights, for each depth scale λ of ``--scales`` (μ = ν = 0), the normals of the
robust initialisation and the lights are turned by P, and the light in attached shadows (where
no direct light arrives, the same pairs for every P) is compared with the one-bounce prediction
of that surface (:func:`unps.lights.reversal.one_bounce`'s kernel, the reversal test's reading):
the share of it explained with one free scale, and that scale. Were the cue to hold, the share
would peak near the true λ. The case's true λ is the scale that brings the final lights nearest the
truth. None of it feeds a stage.
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np
from scipy.optimize import minimize

from unps.geometry import integrate_normals
from unps.lights import with_lights
from unps.lights.reversal import AttachedLight, attached_facets, explained_share
from unps.metrics import angular_error
from unps.solvers.nayar import interreflection_kernel
from unps.solvers.rpca import robust_init

sys.path.insert(0, str(Path(__file__).resolve().parent))
import runs  # noqa: E402
from albedo_entropy import bas_relief  # noqa: E402
from benchmark import capture_options, light_source, study_cases, study_parser  # noqa: E402

SCALES = (0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.12, 1.25, 1.4, 1.6, 1.8, 2.0)


def turned(directions: np.ndarray, p: np.ndarray) -> np.ndarray:
    """(n, 3) unit directions of lights turned by the bas-relief P (l' ∝ P⁻ᵀ l)."""
    out = directions.astype(np.float64) @ np.linalg.inv(p)
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def turned_lights(lights, p: np.ndarray):
    """``lights`` (:class:`unps.data.lights.Lights`) turned by the bas-relief P: scaled lights
    s' = P⁻ᵀ s, so each intensity takes the length the turn gives its direction."""
    scaled = lights.directions.astype(np.float64) @ np.linalg.inv(p)
    length = np.linalg.norm(scaled, axis=1)
    intensities = None if lights.intensities is None else (lights.intensities * length[:, None])
    return dataclasses.replace(lights, directions=(scaled / length[:, None]).astype(np.float32),
                               intensities=None if intensities is None else intensities.astype(np.float32))


def nearest_bas_relief(directions: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(3,) μ, ν, log λ of the bas-relief that brings (n, 3) ``directions`` nearest (n, 3)
    ``truth`` (mean angle)."""
    cost = lambda x: float(angular_error(turned(directions, bas_relief(x[0], x[1], np.exp(x[2]))),  # noqa: E731
                                         truth).mean())
    return minimize(cost, np.zeros(3), method="Nelder-Mead", options={"xatol": 1e-5, "fatol": 1e-5}).x


def depth_scale_error(directions: np.ndarray, truth: np.ndarray, scales: np.ndarray) -> np.ndarray:
    """(k,) mean angle to ``truth`` of ``directions`` turned by the depth scales ``scales``."""
    return np.array([angular_error(turned(directions, bas_relief(0, 0, s)), truth).mean() for s in scales])


def interreflection_reading(subject, lights, scales) -> list[dict]:
    """Per depth scale λ of ``scales``: the attached pairs, their mean level and the share and
    scale of it that the one-bounce prediction of the surface turned by λ explains (see the
    module)."""
    cropped = subject.crop_to_mask(1)
    normals = robust_init(with_lights(cropped, lights), lights.directions, device="cpu").normals
    out = []
    for s in scales:
        p = bas_relief(0.0, 0.0, s)
        turned_normals = normals.astype(np.float64) @ p.T
        turned_normals /= np.maximum(np.linalg.norm(turned_normals, axis=-1, keepdims=True), 1e-12)
        grid, maps, albedo = attached_facets(cropped, turned_lights(lights, p),
                                             turned_normals.astype(np.float32))
        attached = maps["attached"]
        seen = maps["observed"][attached]
        row = {"scale": s, "pairs": int(attached.sum()), "level": float(seen.mean()) if seen.size else 0.0}
        if row["pairs"] >= AttachedLight.MIN_PAIRS:
            depth = np.nan_to_num(integrate_normals(grid.normals, grid.mask))
            predicted = (interreflection_kernel(depth, grid.normals, grid.mask) @ maps["observed"].T).T
            row["share"], row["fit_scale"] = explained_share(seen, (predicted * albedo[None])[attached])
        out.append(row)
    return out


def bas_relief_reading(directions: np.ndarray, truth: np.ndarray) -> dict:
    """(n, 3) ``directions``' error against (n, 3) ``truth``, the error left after the bas-relief
    that brings them nearest it (:func:`nearest_bas_relief`), that bas-relief and the directions."""
    mu, nu, log_lam = nearest_bas_relief(directions, truth)
    undone = turned(directions, bas_relief(mu, nu, np.exp(log_lam)))
    return {"error": float(angular_error(directions, truth).mean()),
            "left": float(angular_error(undone, truth).mean()),
            "mu": float(mu), "nu": float(nu), "lam": float(np.exp(log_lam)),
            "directions": directions.round(6).tolist()}


def run_case(subject, network, stages, scales) -> dict:
    """The network's and the default stages' lights read against the truth
    (:func:`bas_relief_reading`), the depth scale that brings the final lights nearest it, and
    the interreflection cue's reading of each of ``scales`` (:func:`interreflection_reading`, with
    the final lights' error under that scale)."""
    truth = subject.light_directions.astype(np.float64)
    final = stages(subject)
    result = {"n_images": subject.n_images,
              "network": bas_relief_reading(network(subject).directions.astype(np.float64), truth),
              "final": bas_relief_reading(final.directions.astype(np.float64), truth)}
    grid = np.exp(np.linspace(np.log(0.4), np.log(2.5), 201))
    result["true_scale"] = float(grid[depth_scale_error(final.directions, truth, grid).argmin()])
    result["interreflection"] = [
        row | {"error": float(depth_scale_error(final.directions, truth, [row["scale"]])[0])}
        for row in interreflection_reading(subject, final, scales)]
    return result


def read(row: dict) -> dict:
    """The cue's reading of one case: whether it holds (pairs and level at λ = 1 up to the
    reversal test's own floors), the λ of the largest share and the error there."""
    readings = [r for r in row["interreflection"] if "share" in r]
    at_one = min(row["interreflection"], key=lambda r: abs(np.log(r["scale"])))
    holds = (at_one["pairs"] >= AttachedLight.MIN_PAIRS and at_one["level"] >= AttachedLight.MIN_LEVEL
             and bool(readings))
    best = max(readings, key=lambda r: r["share"]) if readings else None
    return {"holds": holds, "level": at_one["level"], "pairs": at_one["pairs"],
            "picked": best["scale"] if best else np.nan, "share": best["share"] if best else np.nan,
            "picked_error": best["error"] if best else np.nan}


def progress(case, row, _result) -> str:
    cue, network, final = read(row), row["network"], row["final"]
    return (f"{'-'.join(case):<28} network {network['error']:6.2f}° (left {network['left']:5.2f}°)  "
            f"final {final['error']:6.2f}° (left {final['left']:5.2f}°, λ {final['lam']:.2f} "
            f"μ {final['mu']:+.2f} ν {final['nu']:+.2f})  interreflection: {cue['pairs']} pairs at "
            f"{100 * cue['level']:.1f} %, true λ {row['true_scale']:.2f}, picked {cue['picked']} "
            f"({cue['picked_error']:.2f}°)")


def report(rows: dict) -> str:
    """Per group and light set: the network's and the final lights' error, each with what the
    nearest bas-relief leaves, the share of the final error that bas-relief is, and on the cases
    where the interreflection cue holds (:func:`read`) the final lights' error as they are, under
    the λ the cue picks, and under the swept λ nearest the truth."""
    lines = [f"{'group':<12} {'set':>4} {'cases':>5} {'network':>8} {'left':>7} {'final':>7} {'left':>7} "
             f"{'share P':>8} {'cue holds':>9} {'there: final':>12} {'at the pick':>11} {'best λ':>9}"]
    for group, label, chosen in runs.by_light_set(rows):
        network = np.mean([[r["network"]["error"], r["network"]["left"]] for r in chosen], axis=0)
        final = np.mean([[r["final"]["error"], r["final"]["left"]] for r in chosen], axis=0)
        held = [(cue, r) for cue, r in ((read(r), r) for r in chosen) if cue["holds"]]
        there = (f"{np.mean([r['final']['error'] for _, r in held]):11.2f}° "
                 f"{np.mean([cue['picked_error'] for cue, _ in held]):10.2f}° "
                 f"{np.mean([best_swept(r) for _, r in held]):8.2f}°") if held else f"{'':>33}"
        lines.append(f"{group:<12} {label:>4} {len(chosen):5d} {network[0]:7.2f}° {network[1]:6.2f}° "
                     f"{final[0]:6.2f}° {final[1]:6.2f}° {100 * (1 - final[1] / final[0]):7.0f} % "
                     f"{len(held):9d} {there}")
    return "\n".join(lines)


def best_swept(row: dict) -> float:
    """The final lights' error turned by the swept depth scale nearest the truth (picked with it)."""
    return float(min(r["error"] for r in row["interreflection"]))


def main() -> None:
    parser = study_parser(__doc__.split("\n")[0], "default: <cache>/bas_relief_left")
    parser.add_argument("--scales", type=float, nargs="+", default=list(SCALES),
                        help="depth scales λ the interreflection cue reads")
    args = parser.parse_args()
    cases = study_cases(args)
    out = args.out or args.cache / "bas_relief_left"
    try:
        runs.claim(out, {"study": "bas_relief_left", "scales": args.scales,
                         "room_light": args.room_light, "weights": runs.weights_digest(None),
                         **capture_options(args)})
    except ValueError as e:
        parser.error(str(e))
    network, _ = light_source([], [])
    stages, _ = light_source(None, [])
    print(report(runs.summaries(cases, out, lambda subject: run_case(subject, network, stages, args.scales),
                                lambda r: r, progress, args.report)))


if __name__ == "__main__":
    main()

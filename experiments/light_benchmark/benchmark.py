"""Light estimation on captures unps has never seen: every light stage, on every object and rig.

    python experiments/light_benchmark/benchmark.py                  # everything (~1.5 h, 2 cores)
    python experiments/light_benchmark/benchmark.py --only benchmark --sets 12
    python experiments/light_benchmark/benchmark.py --stages reversal contour selfcal
    python experiments/light_benchmark/benchmark.py --set selfcal.gbr_weight=0.1 --tag gbr01
    python experiments/light_benchmark/benchmark.py --only benchmark --bounces 2 --tag direct-only
    python experiments/light_benchmark/benchmark.py --room-light 0.01 --tag room0.01
    python experiments/light_benchmark/benchmark.py --only benchmark --outline partial --tag partial

The cases (none of them feeds training):

- **benchmark**: the 24 objects of ``scenes.py`` (meshes and procedural shapes with cavities, thin
  parts and self-shadowing, painted with two or three held-out MERL materials, rendered with
  cast shadows and interreflections), each under a DiLiGenT-like dome of 96 lights and sparse
  rigs of 20 and 12, stored as 8-bit (``floor`` and ``round``) or 16-bit with sensor noise.
  Rendered on first use into ``--cache`` (about 20 s per object on 2 cores), then read from it.
- **single**: the same 24 objects, each in one material alone (``scenes.SINGLE_MATERIAL``: the
  first of its materials, the same pose, lights and camera), as most of DiLiGenT's objects and
  many users' captures are; asked for by name (``--only single``).
- **diligent-rig**: the same 24 objects lit by DiLiGenT's own dome (ball's light directions and
  intensities from ``../shared/data``; ``scenes.ON_DILIGENT_RIG``), its 96 lights and the 20 and 12
  evenly spread over them, where the others have rigs drawn as the network's training draws them;
  asked for by name (``--only diligent-rig``).
- **diligent**: ball, cat and pot1 of ``../shared/data`` at 96 images, and at 20 and 12 images
  evenly spread over their lights (farthest-point order from the light nearest the view).
- **synthetic**: unps's eight rendered subjects (100 images).

``--bounces 2`` renders the first three groups' objects with the direct light alone, cast shadows
included and no interreflection (cached apart): what the stages would give if there were none.
``--outline partial`` renders the first three groups' objects with the pixels they cover in part,
dimmed by the share they cover, and masks the pixels covered at least half (cached apart;
``scenes.OUTLINES``): the outline a photograph and a drawn mask give, where the default's holds
only the pixels the object covers whole.
``--room-light L`` adds to every case the light of a room no dark frame took out
(:func:`with_room_light`): the same in every captured image, L × the captures' 99th percentile
at the object's mean albedo, as photographs outside a blacked-out rig hold (DiLiGenT's ball holds
about 1 % of its 99th percentile in its attached shadows).

Each case runs ``light=estimated`` as ``python -m unps.fit`` does (the network, then the stages
of ``--stages``, default those of ``light=selfcal``; ``--set`` overrides their settings as on the
command line) and prints, per stage, the direction error and intensity error of the lights after
it, flagging a stage that raised the direction error by more than 1° (``+``) or 2° (``++``).
Results are kept case by case in ``--out`` (a run is resumed by rerunning the command), each
row with every light setting it was made with, the defaults resolved: a row made with other
settings (a default changed since) is made again, and says so. The summary compares, per light
count, the final lights with the network's.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from unps.data.catalogue import subjects
from unps.data.diligent import read_diligent, read_diligent_object
from unps.errors import InputError
from unps.solvers.woodham import rgb_albedo
from unps.timing import recording

sys.path.insert(0, str(Path(__file__).resolve().parent))
import runs  # noqa: E402
import scenes  # noqa: E402

DEFAULT_DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
DEFAULT_CACHE = Path("~/.cache/unps/light_benchmark").expanduser()
DILIGENT = ("ball", "cat", "pot1")
GROUPS = ("benchmark", "single", "diligent-rig", "diligent", "synthetic")
DEFAULT_GROUPS = ("benchmark", "diligent", "synthetic")
OUTLINE_HELP = ("the rendered objects' outline: exact (default), the pixels they cover whole and "
                "nothing else; partial, also those they cover in part, dimmed, the mask holding "
                "those covered at least half (rendered on first use and cached apart)")
RESOLUTION_HELP = (f"the rendered objects' captures, pixels a side (default {scenes.RESOLUTION}, at least "
                   f"64; the light network shrinks every capture to its own 64 or 128, as "
                   f"it does a photograph; rendered on first use and cached apart)")
RAISED, RAISED_TWICE = 1.0, 2.0     # degrees: a stage that raised the error by more is flagged


def resolution(text: str) -> int:
    """``--resolution``'s value: a whole number of pixels, at least 64."""
    try:
        side = int(text)
    except ValueError:
        side = 0
    if side < 64:
        raise argparse.ArgumentTypeError(f"a whole number of pixels, at least 64, was expected, got {text!r}")
    return side


def with_room_light(subject, level: float):
    """``subject`` as if the room lit it too, as a dark frame nobody subtracted would leave it: to
    every captured image the same light, ``level`` × the captures' 99th percentile (object pixels,
    grey) × each pixel's Lambertian albedo (least squares with the true normals and lights) over
    the object's mean albedo — a uniform surround, unoccluded, added after the capture was stored.
    The images stay divided by the lights' intensities."""
    mask = subject.mask
    captured = subject.observed_images()
    albedo = rgb_albedo(subject.images[:, mask], subject.normals[mask], subject.light_directions)
    if subject.light_intensities is not None:
        albedo = albedo * subject.light_intensities.mean(0)
    room = level * np.percentile(captured[:, mask].mean(-1), 99) * albedo / albedo.mean()
    lit = captured.copy()
    lit[:, mask] += room[None]
    if subject.light_intensities is not None:
        lit = lit / subject.light_intensities[:, None, None, :]
    return subject.replace(images=lit.astype(np.float32))


def cases(groups, sets, data: Path, cache: Path, names=None, bounces: int = scenes.BOUNCES,
          room_light: float = 0.0, outline: str = "exact", resolution: int = scenes.RESOLUTION):
    """(group, name, light set, function reading the subject) for every case asked for, the
    rendered objects' interreflections traced to ``bounces`` (2: none), their outline drawn as
    ``outline`` (``scenes.OUTLINES``) and their captures ``resolution`` pixels a side, with a
    room's light of ``room_light`` (:func:`with_room_light`; 0: none added)."""
    for group, name, label, read in _cases(groups, sets, data, cache, names, bounces, outline,
                                           resolution):
        if room_light:
            yield group, name, label, lambda read=read: with_room_light(read(), room_light)
        else:
            yield group, name, label, read


def _cases(groups, sets, data: Path, cache: Path, names, bounces: int, outline: str,
           resolution: int):
    for group, objects in (("benchmark", scenes.OBJECTS), ("single", scenes.SINGLE_MATERIAL),
                           ("diligent-rig", scenes.ON_DILIGENT_RIG)):
        if group not in groups:
            continue
        for obj in objects:
            if names and obj.name not in names:
                continue
            obj = replace(obj, bounces=bounces, outline=outline, resolution=resolution)
            for label in sets:
                def read(obj=obj, label=label):
                    folder = scenes.make_captures(obj, data, cache)[label]
                    return read_diligent(folder, name=obj.name,
                                         quantization=scenes.quantization(obj.storage))
                yield group, obj.name, label, read
    if "diligent" in groups:
        for name in DILIGENT:
            if names and name not in names:
                continue
            for label in sets:
                def read(name=name, label=label):
                    subject = read_diligent_object(data / "DiLiGenT", name)
                    if int(label) < subject.n_images:
                        subject = subject.select(scenes.evenly_spread(subject.light_directions, int(label)))
                    return subject
                yield "diligent", name, label, read
    if "synthetic" in groups:
        for name in subjects("synthetic"):
            if not names or name in names:
                yield "synthetic", name, str(100), lambda name=name: synthetic(name)


def case_parser(description: str, groups=DEFAULT_GROUPS) -> argparse.ArgumentParser:
    """A command line that picks the benchmark's cases: where the data and captures are, which
    groups (``groups`` by default), light sets and objects (``--data``, ``--cache``, ``--only``,
    ``--sets``, ``--names``; :func:`cases` takes them)."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--cache", type=Path, default=DEFAULT_CACHE)
    parser.add_argument("--only", nargs="+", choices=GROUPS, default=list(groups))
    parser.add_argument("--sets", nargs="+", choices=list(scenes.LIGHT_SETS), default=list(scenes.LIGHT_SETS))
    parser.add_argument("--names", nargs="*", help="only these objects or subjects")
    parser.add_argument("--room-light", type=float, default=0.0,
                        help="add the light of a room to every image: this share of the captures' "
                             "99th percentile times the albedo (default 0: none)")
    parser.add_argument("--outline", choices=scenes.OUTLINES, default="exact", help=OUTLINE_HELP)
    parser.add_argument("--resolution", type=resolution, default=scenes.RESOLUTION, help=RESOLUTION_HELP)
    return parser


def study_parser(description: str, out_help: str, groups=DEFAULT_GROUPS) -> argparse.ArgumentParser:
    """The command line the light benchmark's studies share: :func:`case_parser`'s, where the
    results are, ``--report`` and ``--threads`` (default 1)."""
    parser = case_parser(description, groups)
    parser.add_argument("--out", type=Path, default=None, help=out_help)
    parser.add_argument("--report", action="store_true", help="print the tables from the cases run so far")
    parser.add_argument("--threads", type=int, default=1, help="torch threads (default 1)")
    return parser


def study_cases(args):
    """The cases a study's parsed ``args`` (:func:`study_parser`) ask for, with logging quiet and
    torch on ``args.threads`` threads."""
    import torch

    logging.basicConfig(level=logging.ERROR, format="%(name)s: %(message)s")
    torch.set_num_threads(args.threads)
    return asked_cases(args)


def asked_cases(args):
    """The cases :func:`case_parser`'s parsed ``args`` ask for (:func:`cases`)."""
    return cases(args.only, args.sets, args.data, args.cache, args.names, room_light=args.room_light,
                 outline=args.outline, resolution=args.resolution)


def capture_options(args) -> dict:
    """The options of :func:`case_parser`'s parsed ``args`` that change the captures, those not at
    their defaults: a study claims its results folder with them, so that none mixes rows of
    captures made otherwise."""
    return ({"room_light": args.room_light} if args.room_light else {}) | \
        ({"outline": args.outline} if args.outline != "exact" else {}) | \
        ({"resolution": args.resolution} if args.resolution != scenes.RESOLUTION else {})


def selfcal_study(description: str, folder: str, made_with: dict, run_case, summarise, progress,
                  report, defaults: dict | None = None) -> None:
    """Run a study of the self-calibration from the command line: :func:`study_parser`'s
    arguments with ``--set`` (its settings over ``defaults``) and ``--tag``; folder
    ``--out`` (default ``<cache>/<folder>/<tag>``) claimed for ``made_with``, the settings and the
    shipped weights' digest; each case run as ``run_case(subject, selfcal)`` and kept there
    (:func:`runs.summaries`, with ``summarise`` and ``progress``; with ``--report`` only those
    kept), and ``report(rows)`` printed."""
    import ast

    from unps.lights.selfcal import SelfCalibration

    parser = study_parser(description, f"default: <cache>/{folder}/<tag>")
    parser.add_argument("--set", dest="settings", nargs="*", default=[],
                        help="self-calibration settings, e.g. prior_weight=0.001")
    parser.add_argument("--tag", default="default", help="names the results folder")
    args = parser.parse_args()
    cases = study_cases(args)
    out = args.out or args.cache / folder / args.tag
    try:
        settings = (defaults or {}) | {key: ast.literal_eval(value)
                                       for key, value in (s.split("=", 1) for s in args.settings)}
        selfcal = SelfCalibration(device="cpu", **settings)
        runs.claim(out, {**made_with, "settings": args.settings, "weights": runs.weights_digest(None),
                         **capture_options(args)})
    except (ValueError, TypeError, SyntaxError) as e:
        parser.error(str(e))
    print(report(runs.summaries(cases, out, lambda subject: run_case(subject, selfcal), summarise,
                                progress, args.report)))


def network_study(parser, args, out: Path, made_with: dict, run_case, report, progress) -> None:
    """Run a study of the network's own lights (no stage after it): folder ``out`` claimed for
    ``made_with`` and the shipped weights' digest, each case :func:`study_cases` gives run as
    ``run_case(subject, network)`` and kept there (:func:`runs.summaries`; with ``--report`` only
    those kept), and ``report(rows)`` printed."""
    cases = study_cases(args)
    try:
        runs.claim(out, {**made_with, "weights": runs.weights_digest(None), **capture_options(args)})
    except ValueError as e:
        parser.error(str(e))
    network, _ = light_source([], [])
    print(report(runs.summaries(cases, out, lambda subject: run_case(subject, network), lambda r: r,
                                progress, args.report)))


def synthetic(name: str):
    return instantiate_node(["fit"], [f"subject={name}"], "subject")()


def instantiate_node(config: list[str], overrides: list[str], key: str):
    """A node of a composed unps config (``key`` dotted, e.g. ``light.selfcal``), instantiated
    (partial nodes stay callables)."""
    from hydra import compose, initialize_config_module
    from hydra.utils import instantiate
    from omegaconf import OmegaConf

    with initialize_config_module("unps.conf", version_base=None):
        node = OmegaConf.select(compose(config[0], overrides=overrides), key)
    return instantiate(OmegaConf.to_container(node, resolve=True), _partial_=True)


def light_node(stages: list[str] | None, settings: list[str]):
    """The ``light`` node of ``python -m unps.fit light=selfcal`` with these stages and
    ``light.<key>=<value>`` overrides (a DictConfig)."""
    overrides = ["light=selfcal", *(f"light.{s}" for s in settings)]
    if stages is not None:
        overrides.append(f"light.stages=[{','.join(stages)}]")
    from hydra import compose, initialize_config_module

    with initialize_config_module("unps.conf", version_base=None):
        return compose("fit", overrides=overrides).light


def light_source(stages: list[str] | None, settings: list[str]):
    """``light=selfcal``'s light source as ``python -m unps.fit`` builds it
    (:func:`unps.pipeline.run.build`), with these stages and ``light.<key>=<value>`` overrides
    (:func:`light_node`); and the names of its stages."""
    from omegaconf import OmegaConf

    from unps.pipeline.run import build

    node = light_node(stages, settings)
    _, source = build(node)
    return source, OmegaConf.to_container(node.stages)


def light_settings(stages: list[str] | None, settings: list[str]) -> dict:
    """Every setting of the light source :func:`light_source` builds, the defaults resolved: what
    each case's row records it was made with."""
    from omegaconf import OmegaConf

    return OmegaConf.to_container(light_node(stages, settings), resolve=True)


def stale(result: dict, made_with: dict) -> str | None:
    """Why a kept row ``result`` cannot stand for a run with the light settings ``made_with``
    (:func:`light_settings`) — the settings that differ, or its having been made before rows
    recorded them — or None where it can."""
    if "light" not in result:
        return "made before rows recorded their light settings"
    changed = runs.differences(result["light"], made_with)
    if not changed:
        return None
    return f"made with other light settings ({runs.listed(changed)})"


def weights_used(settings: list[str]) -> str:
    """The digest (:func:`runs.weights_digest`) of the light-network weights a run with these
    settings reads: the file of the last ``checkpoint=`` setting, else the shipped weights.

    Raises:
        InputError: the weights file is not there.
    """
    given = [s.split("=", 1)[1] for s in settings if s.startswith("checkpoint=")]
    return runs.weights_digest(given[-1] if given else None)


def run_case(source, subject) -> dict:
    """The lights' errors after each stage, each stage's verdict, and the seconds it took."""
    with recording() as seconds:
        start = time.perf_counter()
        lights = source(subject)
        total = time.perf_counter() - start
    stages = [{"stage": v.stage, "outcome": v.outcome, "dir": v.errors["light_dir_mae"],
               "slant": v.errors["light_slant_bias"], "int": v.errors.get("light_int_err"),
               "reason": v.reason, "evidence": v.evidence} for v in lights.verdicts]
    return {"stages": stages, "seconds": total, "stage_seconds": dict(seconds),
            "n_images": subject.n_images}


def flag(before: float, after: float) -> str:
    raised = after - before
    return "++" if raised > RAISED_TWICE else "+" if raised > RAISED else ""


def row(group: str, name: str, label: str, result: dict, stage_names: list[str]) -> str:
    errors = {s["stage"]: s for s in result["stages"]}
    network = errors["network"]["dir"]
    cells, flags, previous = [f"{network:>7.2f}°"], [], network
    for stage in stage_names:
        s = errors[stage]
        mark = flag(previous, s["dir"])
        if mark:
            flags.append(f"{stage}{mark}")
        cells.append(f"{s['dir']:>7.2f}°{s['outcome'][0]}")
        previous = s["dir"]
    final = result["stages"][-1]
    intensity = final["int"]
    return (f"{group:<9} {name:<12} {label:>3} " + " ".join(cells)
            + f" {final['dir']:>7.2f}° {intensity if intensity is not None else float('nan'):>6.3f}"
            f" {result['seconds']:>5.0f}s  {' '.join(flags)}")


def median_slant(chosen: list[dict], stage: int) -> str:
    """The median over cases of a stage's light slant bias (``light_slant_bias``: < 0 where the
    lights are read nearer the view axis than they are), or a dash where a result predates it."""
    values = [r["stages"][stage].get("slant") for r in chosen]
    return f"{np.median(values):>+7.2f}°" if values and None not in values else f"{'—':>8}"


def summary(results: dict, stage_names: list[str]) -> str:
    """Per group and light count: mean network and final error, their ratio, the flags, and the
    median slant bias of the network's and the final lights."""
    lines = [f"\n{'group':<9} {'set':>4} {'cases':>5} {'network':>8} {'final':>8} {'ratio':>6} "
             f"{'>1° raises':>10} {'>2° raises':>10} {'worst raise':>12} {'slant, network':>14} {'final':>8}"]
    keys = sorted({(k[0], k[2]) for k in results}, key=lambda k: (GROUPS.index(k[0]), -int(k[1])))
    for group, label in keys:
        chosen = [r for k, r in results.items() if k[0] == group and k[2] == label]
        network = np.mean([r["stages"][0]["dir"] for r in chosen])
        final = np.mean([r["stages"][-1]["dir"] for r in chosen])
        raises = [s["dir"] - r["stages"][i]["dir"] for r in chosen
                  for i, s in enumerate(r["stages"][1:])]
        lines.append(f"{group:<9} {label:>4} {len(chosen):>5} {network:>7.2f}° {final:>7.2f}° "
                     f"{final / network:>6.2f} {sum(x > RAISED for x in raises):>10} "
                     f"{sum(x > RAISED_TWICE for x in raises):>10} {max(raises, default=0):>11.2f}° "
                     f"{median_slant(chosen, 0):>14} {median_slant(chosen, -1)}")
    return "\n".join(lines)


def catalogue() -> str:
    """The benchmark's objects as a Markdown table."""
    lines = ["| object | shape | materials (held-out MERL) | stored as |", "| --- | --- | --- | --- |"]
    for obj in scenes.OBJECTS:
        builder, arguments = obj.shape
        shape = builder + "(" + ", ".join(f"{k}={v}" for k, v in arguments.items()) + ")"
        lines.append(f"| {obj.name} | `{shape}` | {', '.join(obj.materials)} | {obj.storage} |")
    return "\n".join(lines)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--cache", type=Path, default=DEFAULT_CACHE,
                        help="where the benchmark's captures are rendered and kept")
    parser.add_argument("--out", type=Path, default=None,
                        help="where each case's result is kept (default: <cache>/results/<tag>)")
    parser.add_argument("--tag", default="default", help="names the results folder")
    parser.add_argument("--only", nargs="+", choices=GROUPS, default=list(DEFAULT_GROUPS))
    parser.add_argument("--sets", nargs="+", choices=list(scenes.LIGHT_SETS), default=list(scenes.LIGHT_SETS))
    parser.add_argument("--names", nargs="*", help="only these objects or subjects")
    parser.add_argument("--stages", nargs="*", default=None,
                        help="as light.stages (default: light=selfcal's)")
    parser.add_argument("--set", dest="settings", nargs="*", default=[],
                        help="light.<key>=<value> overrides, e.g. selfcal.steps=1000")
    parser.add_argument("--threads", type=int, default=1,
                        help="torch threads (default 1, as the other studies: two runs side by side at "
                             "torch's default of one thread per core took 60 times as long a case)")
    parser.add_argument("--bounces", type=int, default=scenes.BOUNCES,
                        help=f"the rendered objects' interreflections traced to this many bounces "
                             f"(default {scenes.BOUNCES}; 2: none, the direct light and its cast shadows "
                             f"alone; rendered on first use and cached apart)")
    parser.add_argument("--room-light", type=float, default=0.0,
                        help="add the light of a room to every image: this share of the captures' "
                             "99th percentile times the albedo (default 0: none; with_room_light)")
    parser.add_argument("--outline", choices=scenes.OUTLINES, default="exact", help=OUTLINE_HELP)
    parser.add_argument("--resolution", type=resolution, default=scenes.RESOLUTION, help=RESOLUTION_HELP)
    parser.add_argument("--list", action="store_true", help="print the objects as a Markdown table and stop")
    parser.add_argument("--verbose", action="store_true")
    args = parser.parse_args()
    if args.bounces < 2:
        parser.error(f"--bounces is the path tracer's longest path, at least 2 (direct light), "
                     f"got {args.bounces}")
    if args.room_light < 0:
        parser.error(f"--room-light is a share of the captures' 99th percentile, at least 0, got "
                     f"{args.room_light}")
    if args.list:
        print(catalogue())
        return
    logging.basicConfig(level=logging.INFO if args.verbose else logging.ERROR,
                        format="%(name)s: %(message)s")
    import torch
    torch.set_num_threads(args.threads)
    from hydra.errors import ConfigCompositionException
    try:
        source, stage_names = light_source(args.stages, args.settings)
        made_with = light_settings(args.stages, args.settings)
    except (InputError, ConfigCompositionException) as e:
        parser.error(str(e))
    out = args.out or args.cache / "results" / args.tag
    try:
        claimed = {"stages": stage_names, "settings": args.settings, "scenes": scenes.SCENE_VERSION,
                   "weights": weights_used(args.settings)}
        if args.bounces != scenes.BOUNCES:
            claimed["bounces"] = args.bounces
        claimed |= capture_options(args)
        runs.claim(out, claimed)
    except (ValueError, InputError) as e:
        parser.error(str(e))
    print(f"stages: network → {' → '.join(stage_names) or '(none)'}; settings: "
          f"{' '.join(args.settings) or 'defaults'}"
          + ("" if args.bounces == scenes.BOUNCES else f"; renders traced to {args.bounces} bounces")
          + (f"; a room's light of {args.room_light:g} added" if args.room_light else "")
          + ("" if args.outline == "exact" else f"; outlines {args.outline}")
          + ("" if args.resolution == scenes.RESOLUTION else f"; {args.resolution} px a side")
          + f"; results in {out}")
    print(f"{'group':<9} {'case':<12} {'set':>3} {'network':>8} "
          + " ".join(f"{s:>9}" for s in stage_names) + f" {'final':>8} {'int':>6} {'time':>6}  raised")
    results = {}
    for group, name, label, read in cases(args.only, args.sets, args.data, args.cache, args.names,
                                          args.bounces, args.room_light, args.outline, args.resolution):
        path = out / f"{group}-{name}-{label}.json"
        result = json.loads(path.read_text()) if path.is_file() else None
        why = None if result is None else stale(result, made_with)
        if why:
            print(f"{group:<9} {name:<12} {label:>3} run again: its row was {why}")
        if result is None or why:
            try:
                subject = read()
            except InputError as e:
                print(f"{group:<9} {name:<12} {label:>3} skipped: {e}")
                continue
            result = {**run_case(source, subject), "light": made_with}
            path.write_text(json.dumps(result, indent=1))
        results[group, name, label] = result
        print(row(group, name, label, result, stage_names), flush=True)
    print(summary(results, stage_names))


if __name__ == "__main__":
    main()

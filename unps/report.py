"""``python -m unps.report <sweep folder> [--out DIR]``: the table and figures of a study.

    python -m unps.fit -m experiment=noise          # runs land in multirun/noise/<overrides>/
    python -m unps.report multirun/noise            # writes multirun/noise/report/
    python -m unps.report multirun/noise --out experiments/noise

Every run folder with a ``metrics.json`` under the sweep folder is read; its ``study`` (set by
``experiment=…``) picks the report: ``table1``, ``noise``, ``facets``, ``rose``, ``light_stats``,
``baselines``, or, for any other sweep, one row per run with the settings that vary. Folders
that a sweep started but did not finish are listed, never silently left out. The report is
``results.md`` (markdown tables, next to the paper's published figures where it has them) and
PNG figures; it is a function of the runs' files only, so a rerun of the same sweep with the
same seed on the same kind of machine regenerates it (run times apart).
"""

from __future__ import annotations

import argparse
import json
import logging
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from unps.errors import InputError, exit_on_bad_input
from unps.io.files import atomic_path

log = logging.getLogger("unps.report")

SYNTHETIC = ("Vase", "Golf-ball", "Face", "Tablet1", "Tablet2", "BrokenPot", "Rose", "Sphere")
DILIGENT = ("ball", "bear", "buddha", "cat", "cow", "goblet", "harvest", "pot1", "pot2", "reading")
PAPER_SUBJECTS = SYNTHETIC[:6]

# Published normal MAE (degrees) of Kaya et al. 2021: supplementary Table 1 (synthetic subjects,
# preset and resolution of the paper) and the main paper's DiLiGenT table (estimated lights).
PAPER_MAE = {
    "gt": {"Vase": 16.40, "Golf-ball": 14.23, "Face": 14.24, "Tablet1": 10.77, "Tablet2": 4.49,
           "BrokenPot": 15.92},
    "estimated": {"Vase": 19.91, "Golf-ball": 11.04, "Face": 13.43, "Tablet1": 12.37,
                  "Tablet2": 13.12, "BrokenPot": 18.55, "ball": 3.78, "cat": 7.91, "pot1": 8.75},
}
PAPER_FACETS = {"ball": 985, "cat": 2808, "pot1": 3601, "bear": 2585, "pot2": 2193, "buddha": 2787,
                "goblet": 1636, "reading": 1723, "cow": 1651, "harvest": 3582, "Vase": 1280,
                "Golf-ball": 468, "Face": 435, "Tablet1": 1610, "Tablet2": 437, "BrokenPot": 1046}
PAPER_ROSE_MAE = 60.82
PAPER_SPHERE_LIGHT_MAE = 6.31
METHODS = ("woodham", "rpca", "nayar", "unps")
METHOD_NAMES = {"woodham": "Woodham", "rpca": "robust init. (RPCA)", "nayar": "Nayar (15 it.)",
                "unps": "ours (unps)"}
LIGHTS = ("gt", "estimated", "refine")


@dataclass(frozen=True)
class Run:
    """One finished run: its folder and its ``metrics.json``."""

    folder: Path
    metrics: dict

    def __getitem__(self, key):
        return self.metrics.get(key)


def collect(sweep: Path) -> tuple[list[Run], list[Path]]:
    """Finished runs (a ``metrics.json``) and unfinished ones (a ``.hydra`` folder without it)
    under ``sweep``, in path order.

    Raises:
        InputError: ``sweep`` is not a folder or holds no finished run.
    """
    if not sweep.is_dir():
        raise InputError(f"{sweep}: not a folder (expected a sweep folder, e.g. multirun/noise)")
    runs = []
    for path in sorted(sweep.rglob("metrics.json")):
        try:
            runs.append(Run(path.parent, json.loads(path.read_text())))
        except json.JSONDecodeError as error:
            raise InputError(f"{path}: not valid JSON ({error})") from error
    unfinished = sorted(p.parent for p in sweep.rglob(".hydra") if not (p.parent / "metrics.json").exists())
    if not runs:
        raise InputError(f"{sweep}: no finished run (no metrics.json below it)")
    return runs, unfinished


def subject_order(names: Iterable[str]) -> list[str]:
    """Synthetic subjects in the paper's order, then DiLiGenT's, then any others by name."""
    known = SYNTHETIC + DILIGENT
    names = set(names)
    return [n for n in known if n in names] + sorted(names - set(known))


def pick(runs: Sequence[Run], **where) -> Run | None:
    """The run whose metrics match every ``key=value``; None if there is none.

    Raises:
        InputError: more than one run matches (a sweep folder mixing two sweeps).
    """
    found = [r for r in runs if all(r[k] == v for k, v in where.items())]
    if len(found) > 1:
        raise InputError(f"{len(found)} runs match {where}: {', '.join(str(r.folder) for r in found)}; "
                         f"report one sweep at a time")
    return found[0] if found else None


def mae(run: Run | None) -> float | None:
    return None if run is None else run["normal_mae"]


def fmt(value: float | None, digits: int = 2, sign: bool = False) -> str:
    if value is None or not np.isfinite(value):
        return "—"
    return f"{value:+.{digits}f}" if sign else f"{value:.{digits}f}"


def markdown_table(header: Sequence[str], rows: Iterable[Sequence[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


def mean_of(values: Iterable[float | None]) -> float | None:
    """The mean, or None when any value is missing (a partial average would mislead)."""
    values = list(values)
    if not values or any(v is None for v in values):
        return None
    return float(np.mean(values))


def settings_line(runs: Sequence[Run]) -> str:
    """Preset, images and resolution of the runs, as the report's header states them."""
    def distinct(key, show=str):
        return ", ".join(sorted({show(r[key]) for r in runs if r[key] is not None})) or "—"
    resolution = distinct("resolution", lambda v: f"{v[0]}×{v[1]}")
    return (f"{len(runs)} runs; method {distinct('method')}; preset {distinct('preset')}; "
            f"images {distinct('n_images')}; resolution (H×W) {resolution}; seed {distinct('seed')}")


# ----------------------------------------------------------------------------- figures


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save(fig, path: Path) -> Path:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110, bbox_inches="tight", metadata={"Software": None})
    _pyplot().close(fig)
    return path


def read_rgb(path: Path) -> np.ndarray | None:
    from unps.io.images import read_image

    return read_image(path) if path.exists() else None


def error_picture(folder: Path) -> np.ndarray | None:
    """The run's ``error.npy`` through the error colour map, on the outputs' fixed 0–45° scale."""
    from unps.io.pictures import error_rgb

    path = folder / "error.npy"
    if not path.exists():
        return None
    error = np.load(path).astype(np.float32)
    return error_rgb(error, np.isfinite(error))


def picture_grid(cells: Sequence[Sequence[tuple[str, np.ndarray | None]]], title: str):
    """A figure of rows of titled pictures (None leaves a blank cell), with the error colour bar."""
    import matplotlib
    from unps.io.pictures import ERROR_RANGE_DEG

    plt = _pyplot()
    n_rows, n_cols = len(cells), max(len(row) for row in cells)
    fig, axes = plt.subplots(n_rows, n_cols, figsize=(2.2 * n_cols + 0.6, 2.3 * n_rows + 0.4),
                             squeeze=False)
    for r, row in enumerate(cells):
        for c in range(n_cols):
            ax = axes[r][c]
            ax.set_axis_off()
            if c < len(row) and row[c][1] is not None:
                ax.imshow(row[c][1], interpolation="nearest")
                ax.set_title(row[c][0], fontsize=8)
    mappable = matplotlib.cm.ScalarMappable(matplotlib.colors.Normalize(0, ERROR_RANGE_DEG), "viridis")
    bar = fig.colorbar(mappable, ax=axes.ravel().tolist(), fraction=0.02, pad=0.01, extend="max")
    bar.set_label("angular error (°)", fontsize=8)
    fig.suptitle(title, fontsize=10)
    return fig


# ----------------------------------------------------------------------------- studies


def report_table1(runs: Sequence[Run], out: Path) -> tuple[str, list[Path]]:
    subjects = subject_order(r["subject"] for r in runs)
    found = {(s, light): pick(runs, subject=s, light=light) for s in subjects for light in LIGHTS}
    ours = {key: mae(run) for key, run in found.items()}
    rows = []
    for s in subjects:
        gt, est, refine = (ours[s, light] for light in LIGHTS)
        paper_gt, paper_est = PAPER_MAE["gt"].get(s), PAPER_MAE["estimated"].get(s)
        light_errors = " → ".join(fmt(found[s, light]["light_dir_mae"]) for light in LIGHTS[1:]
                                  if found[s, light] is not None)
        rows.append([s, fmt(gt), fmt(est), fmt(None if None in (gt, est) else est - gt, sign=True),
                     fmt(refine), light_errors or "—", fmt(paper_gt), fmt(paper_est),
                     fmt(None if None in (paper_gt, paper_est) else paper_est - paper_gt, sign=True)])
    groups = [("average, the paper's six", PAPER_SUBJECTS)]
    if set(subjects) != set(PAPER_SUBJECTS):
        groups.append(("average, all", subjects))
    for label, group in groups:
        if not set(group) <= set(subjects):
            continue
        gt, est, refine = (mean_of(ours[s, light] for s in group) for light in LIGHTS)
        paper_gt = mean_of(PAPER_MAE["gt"].get(s) for s in group)
        paper_est = mean_of(PAPER_MAE["estimated"].get(s) for s in group)
        rows.append([f"**{label}**", fmt(gt), fmt(est),
                     fmt(None if None in (gt, est) else est - gt, sign=True), fmt(refine), "",
                     fmt(paper_gt), fmt(paper_est),
                     fmt(None if None in (paper_gt, paper_est) else paper_est - paper_gt, sign=True)])
    table = markdown_table(["subject", "GT light", "estimated", "est. − GT", "refine",
                            "light error: est. → refined", "paper GT", "paper est.", "paper est. − GT"],
                           rows)
    table += ("\n\nNormal MAE in degrees; the light error is the direction MAE of the lights used "
              "(degrees).")

    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(1.1 * len(subjects) + 2, 3.6))
    x = np.arange(len(subjects))
    for k, (light, colour) in enumerate(zip(LIGHTS, ("tab:green", "tab:red", "tab:blue"))):
        values = [ours[s, light] if ours[s, light] is not None else np.nan for s in subjects]
        ax.bar(x + (k - 1) * 0.27, values, 0.27, color=colour, label=f"ours, light={light}")
    for light, marker in (("gt", "o"), ("estimated", "D")):
        values = [PAPER_MAE[light].get(s, np.nan) for s in subjects]
        ax.plot(x, values, marker, mfc="none", mec="black", ls="none", label=f"paper, {light}")
    ax.set_xticks(x, subjects)
    ax.set_ylabel("normal MAE (°)")
    ax.legend(fontsize=7, ncol=2)
    ax.grid(axis="y", alpha=0.3)
    ax.set_title("Calibrated vs uncalibrated (supplementary Table 1)")
    figure = save(fig, out / "table1.png")
    return table, [figure]


def report_noise(runs: Sequence[Run], out: Path) -> tuple[str, list[Path]]:
    import matplotlib.ticker

    subjects = subject_order(r["subject"] for r in runs)
    sigmas = sorted({r["noise"] for r in runs})
    found = {(s, sigma): pick(runs, subject=s, noise=sigma) for s in subjects for sigma in sigmas}
    grid = {key: mae(run) for key, run in found.items()}
    average = {sigma: mean_of(grid[s, sigma] for s in subjects) for sigma in sigmas}
    header = ["subject"] + [f"σ = {sigma:g}" for sigma in sigmas]
    rows = [[s] + [fmt(grid[s, sigma]) for sigma in sigmas] for s in subjects]
    rows.append(["**average**"] + [fmt(average[sigma]) for sigma in sigmas])
    table = "Normal MAE (°):\n\n" + markdown_table(header, rows)
    light_rows = [[s] + [fmt(None if found[s, sigma] is None else found[s, sigma]["light_dir_mae"])
                         for sigma in sigmas] for s in subjects]
    if any(cell != "—" for row in light_rows for cell in row[1:]):
        table += ("\n\nDirection MAE (°) of the lights used (the light network sees the noisy images "
                  "too):\n\n" + markdown_table(header, light_rows))

    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(5.5, 3.6))
    for s in subjects:
        ax.plot(sigmas, [grid[s, sigma] if grid[s, sigma] is not None else np.nan for sigma in sigmas],
                "o-", lw=1, ms=3, label=s)
    ax.plot(sigmas, [average[sigma] if average[sigma] is not None else np.nan for sigma in sigmas],
            "s-", color="black", lw=2.5, label="average")
    ax.set_xlabel("noise σ (relative to the 99th percentile of the pixels)")
    ax.set_ylabel("normal MAE (°), log scale")
    ax.set_yscale("log")
    for axis_format in (ax.yaxis.set_major_formatter, ax.yaxis.set_minor_formatter):
        axis_format(matplotlib.ticker.FormatStrFormatter("%g"))
    ax.set_xticks(sigmas)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    ax.set_title("MAE against image noise (supplementary Fig. 2)")
    return table, [save(fig, out / "noise.png")]


def facet_setting(run: Run) -> str:
    return f"×{run['facet_downsample']}" if run["interreflection"] else "off"


def report_facets(runs: Sequence[Run], out: Path) -> tuple[str, list[Path]]:
    subjects = subject_order(r["subject"] for r in runs)
    settings = sorted({facet_setting(r) for r in runs}, key=lambda s: (s == "off", len(s), s))
    cell = {(facet_setting(r), r["subject"]): r for r in runs}
    if len(cell) != len(runs):
        raise InputError("two runs share a subject and facet setting; report one sweep at a time")

    def rows(value: Callable[[Run], float | None], digits: int) -> list[list[str]]:
        body = [[s] + [fmt(value(cell[k]) if (k := (setting, s)) in cell else None, digits)
                       for setting in settings] for s in subjects]
        averages = [mean_of(value(cell[setting, s]) if (setting, s) in cell else None for s in subjects)
                    for setting in settings]
        return body + [["**average**"] + [fmt(a, digits) for a in averages]]

    header = ["subject"] + settings
    facet_rows = [[s] + [str(cell[setting, s]["facets"]) if (setting, s) in cell else "—"
                         for setting in settings if setting != "off"]
                  + [str(PAPER_FACETS[s]) if s in PAPER_FACETS else "—"] for s in subjects]
    table = "\n\n".join([
        "Normal MAE (°):\n\n" + markdown_table(header, rows(lambda r: r["normal_mae"], 2)),
        "Fit time (s, the whole method: robust initialisation, kernel updates and steps):\n\n"
        + markdown_table(header, rows(lambda r: r["runtime_s"], 0)),
        "Facets in the interreflection kernel (the paper's counts are at its own resolution, ×4):\n\n"
        + markdown_table(["subject"] + [s for s in settings if s != "off"] + ["paper (×4)"], facet_rows)])

    # MAE as the change from interreflection=off where that run exists: the subjects' MAEs differ
    # by tens of degrees, the settings' by tenths.
    def mae_shown(setting: str, s: str) -> float:
        if (setting, s) not in cell:
            return np.nan
        return cell[setting, s]["normal_mae"] - (cell["off", s]["normal_mae"] if ("off", s) in cell else 0)

    relative = any(("off", s) in cell for s in subjects)
    plt = _pyplot()
    fig, (ax_mae, ax_time) = plt.subplots(1, 2, figsize=(9, 3.4))
    x = np.arange(len(settings))
    for s in subjects:
        ax_mae.plot(x, [mae_shown(setting, s) for setting in settings], "o-",
                    label=s if ("off", s) in cell or not relative else f"{s} (absolute)")
        ax_time.plot(x, [cell[k]["runtime_s"] if (k := (setting, s)) in cell else np.nan
                         for setting in settings], "o-", label=s)
    mae_label = "normal MAE − MAE with it off (°)" if relative else "normal MAE (°)"
    if relative:
        ax_mae.axhline(0, color="grey", lw=0.8)
    for ax, label in ((ax_mae, mae_label), (ax_time, "fit time (s)")):
        ax.set_xticks(x, settings)
        ax.set_xlabel("facet grid (interreflection kernel)")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    ax_mae.legend(fontsize=7)
    fig.suptitle("Facet downsampling of the interreflection kernel")
    return table, [save(fig, out / "facets.png")]


def qualitative_row(run: Run) -> list[tuple[str, np.ndarray | None]]:
    label = f"{METHOD_NAMES.get(run['method'], run['method'])}, light={run['light']}"
    return [(f"{label}\n{fmt(run['normal_mae'])}°", read_rgb(run.folder / "normals.png")),
            ("error", error_picture(run.folder))]


def report_rose(runs: Sequence[Run], out: Path) -> tuple[str, list[Path]]:
    ordered = sorted(runs, key=lambda r: (LIGHTS.index(r["light"]) if r["light"] in LIGHTS else 9))
    rows = [[r["subject"], r["light"], fmt(r["normal_mae"]), fmt(r["normal_median"]),
             f"{100 * r['acc_30']:.1f} %"] for r in ordered]
    rows.append(["Rose (paper)", "estimated", fmt(PAPER_ROSE_MAE), "—", "—"])
    table = markdown_table(["subject", "light", "MAE (°)", "median (°)", "< 30°"], rows)
    cells = [[("ground truth", read_rgb(r.folder / "normals_gt.png")), *qualitative_row(r),
              ("observed / reconstructed / difference", read_rgb(r.folder / "reconstruction.png"))]
             for r in ordered]
    fig = picture_grid(cells, "The failure case: Rose (supplementary Fig. 1)")
    return table, [save(fig, out / "rose.png")]


def read_light_file(path: Path) -> np.ndarray:
    """(n, 3) directions from a ``lights.txt`` written by :func:`unps.lights.write_lights`."""
    return np.loadtxt(path, ndmin=2)[:, :3]


def report_light_stats(runs: Sequence[Run], out: Path) -> tuple[str, list[Path]]:
    by_subject = {r["subject"]: r for r in runs}
    subjects = subject_order(by_subject)
    rows = [[s, str(by_subject[s]["n_images"]), fmt(by_subject[s]["light_dir_mae"]),
             fmt(by_subject[s]["light_int_err"], 3)] for s in subjects]
    rows.append(["Sphere (paper)", "—", fmt(PAPER_SPHERE_LIGHT_MAE), "—"])
    table = markdown_table(["subject", "images", "direction MAE (°)", "intensity error"], rows)
    figures = []
    plt = _pyplot()
    for s in subjects:
        folder = by_subject[s].folder
        if not (folder / "lights_gt.txt").exists():
            continue
        true, est = read_light_file(folder / "lights_gt.txt"), read_light_file(folder / "lights.txt")
        order = np.argsort(np.arctan2(true[:, 1], true[:, 0]))
        fig, axes = plt.subplots(3, 1, figsize=(8, 6), sharex=True)
        for k, (ax, axis) in enumerate(zip(axes, "xyz")):
            ax.plot(true[order, k], "-", color="tab:green", label="ground truth")
            ax.plot(est[order, k], ".-", color="tab:red", lw=0.8, ms=3, label="estimated")
            ax.set_ylabel(f"l_{axis}")
            ax.grid(alpha=0.3)
        axes[0].legend(loc="upper right", fontsize=8)
        axes[0].set_title(f"{s}: light directions per image (MAE {fmt(by_subject[s]['light_dir_mae'])}°)")
        axes[-1].set_xlabel("image (ordered by true azimuth)")
        figures.append(save(fig, out / f"lights_{s}.png"))
    return table, figures


def report_baselines(runs: Sequence[Run], out: Path) -> tuple[str, list[Path]]:
    subjects = subject_order(r["subject"] for r in runs)
    methods = [m for m in METHODS if any(r["method"] == m for r in runs)]
    grid = {(s, m): pick(runs, subject=s, method=m) for s in subjects for m in methods}
    rows = [[s] + [fmt(mae(grid[s, m])) for m in methods] for s in subjects]
    rows.append(["**average**"] + [fmt(mean_of(mae(grid[s, m]) for s in subjects)) for m in methods])
    table = markdown_table(["subject"] + [METHOD_NAMES[m] for m in methods], rows)
    figures = []
    for s in subjects:
        present = [grid[s, m] for m in methods if grid[s, m] is not None]
        gt = next((read_rgb(r.folder / "normals_gt.png") for r in present), None)
        cells = [[("ground truth", gt)] + [(f"{METHOD_NAMES[r['method']]}\n{fmt(r['normal_mae'])}°",
                                           read_rgb(r.folder / "normals.png")) for r in present],
                 [("", None)] + [("error", error_picture(r.folder)) for r in present]]
        figures.append(save(picture_grid(cells, f"{s} (light={present[0]['light']})"), out / f"grid_{s}.png"))
    reflectance = [(s, read_rgb(grid[s, "unps"].folder / "reflectance.png"))
                   for s in subjects if "unps" in methods and grid[s, "unps"] is not None]
    reflectance = [(s, image) for s, image in reflectance if image is not None]
    if reflectance:
        plt = _pyplot()
        width = 10.0   # inches; each row as tall as its contact sheet at this width, plus its title
        heights = [width * image.shape[0] / image.shape[1] + 0.3 for _, image in reflectance]
        fig, axes = plt.subplots(len(reflectance), 1, figsize=(width, sum(heights) + 0.5), squeeze=False,
                                 gridspec_kw={"height_ratios": heights}, layout="constrained")
        for ax, (s, image) in zip(axes[:, 0], reflectance):
            ax.imshow(image, interpolation="nearest")
            ax.set_axis_off()
            ax.set_title(s, fontsize=8, loc="left")
        fig.suptitle("Reflectance maps of the fit, 6 of the images (supplementary Figs. 13–14)")
        figures.append(save(fig, out / "reflectance_maps.png"))
    return table, figures


def report_sweep(runs: Sequence[Run], out: Path) -> tuple[str, list[Path]]:
    """Any other sweep: one row per run, with the settings that differ between runs."""
    keys = ["subject", "method", "light", "noise", "preset", "interreflection", "facet_downsample", "seed"]
    varying = [k for k in keys if len({json.dumps(r[k]) for r in runs}) > 1] or ["subject"]
    rows = [[str(r[k]) for k in varying] + [fmt(r["normal_mae"]), fmt(r["light_dir_mae"]),
                                           fmt(r["runtime_s"], 1), r.folder.name] for r in runs]
    return markdown_table(varying + ["normal MAE (°)", "light MAE (°)", "time (s)", "folder"], rows), []


REPORTS: dict[str, tuple[str, Callable]] = {
    "table1": ("Calibrated vs uncalibrated light (supplementary Table 1)", report_table1),
    "noise": ("Robustness to image noise (supplementary Fig. 2)", report_noise),
    "facets": ("Facet downsampling of the interreflection kernel", report_facets),
    "rose": ("The failure case: Rose (supplementary case study 3)", report_rose),
    "light_stats": ("Light estimation statistics (supplementary Fig. 6)", report_light_stats),
    "baselines": ("Baselines and qualitative results (supplementary Figs. 7–14)", report_baselines),
}


def report(sweep: Path, out: Path | None = None) -> Path:
    """Write ``results.md`` and the figures of the study in ``sweep`` into ``out``
    (default ``<sweep>/report``); returns the markdown's path.

    Raises:
        InputError: no finished run, or runs of different studies in one folder.
    """
    runs, unfinished = collect(sweep)
    studies = {r["study"] for r in runs}
    if len(studies) > 1:
        names = ", ".join(sorted(map(str, studies)))
        raise InputError(f"{sweep}: runs of several studies ({names}); report one sweep folder at a time")
    study = studies.pop()
    title, write = REPORTS.get(study, ("Sweep", report_sweep))
    out = Path(out) if out is not None else sweep / "report"
    out.mkdir(parents=True, exist_ok=True)
    table, figures = write(runs, out)
    lines = [f"# {title}", "", f"Study `{study}`: {settings_line(runs)}.", "", table, ""]
    lines += [f"![{f.stem}]({f.name})" for f in figures]
    if unfinished:
        lines += ["", f"**{len(unfinished)} unfinished runs** (no metrics.json): "
                  + ", ".join(f"`{p.relative_to(sweep)}`" for p in unfinished)]
    path = out / "results.md"
    with atomic_path(path) as tmp:
        tmp.write_text("\n".join(lines) + "\n")
    log.info("%s: %d runs → %s (%d figures)", study, len(runs), path, len(figures))
    return path


@exit_on_bad_input
def report_and_print(args: argparse.Namespace) -> None:
    print(report(args.sweep, args.out).read_text())


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description="Tables and figures of one study's sweep folder.")
    parser.add_argument("sweep", type=Path, help="the sweep folder, e.g. multirun/noise")
    parser.add_argument("--out", type=Path, help="where to write (default: <sweep>/report)")
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    report_and_print(parser.parse_args(argv))


if __name__ == "__main__":
    main()

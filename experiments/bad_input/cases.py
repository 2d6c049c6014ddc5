"""Bad input, case by case, through the command line as a user types it.

    python experiments/bad_input/cases.py                  # every case; writes docs/bad_input.md
    python experiments/bad_input/cases.py --only black      # the cases whose name contains "black"

Each case builds its input in a scratch folder (a 32×32 rendered sphere written as a plain
folder of 16-bit PNGs, then broken one way), runs ``python -m unps.fit`` on it, and records the
exit code, the last line on stderr and the warnings in ``metrics.json``. A case passes when the
exit code is the expected one, the message names the culprit, no traceback is printed and, for
an error, nothing is written. ``tests/test_cli_bad_input.py`` runs every case.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from unps.data.analytic import render_lambertian
from unps.data.writer import write_diligent

DOCS = Path(__file__).resolve().parents[2] / "docs" / "bad_input.md"
WOODHAM = ["method=woodham"]


@dataclass(frozen=True)
class Case:
    """One bad input: ``build(folder)`` writes what it needs under ``folder`` and returns the
    command-line arguments; the run must exit with ``code`` and show ``culprit``."""

    name: str
    what: str
    build: Callable[[Path], list[str]]
    code: int
    culprit: str


def sphere_folder(root: Path, n_lights: int = 12, transform=None, lights=None) -> Path:
    """A rendered sphere as a plain folder (16-bit PNGs, mask, lights), optionally changed."""
    subject = render_lambertian("sphere", size=32, n_lights=n_lights, seed=3)
    if transform is not None:
        subject = subject.replace(images=transform(subject.observed_images()), light_intensities=None)
    if lights is not None:
        subject = subject.replace(light_directions=np.asarray(lights, np.float32))
    folder = root / "capture"
    write_diligent(subject, folder)
    return folder


def folder_args(folder: Path, *extra: str) -> list[str]:
    return ["subject=folder", f"subject.root={folder}", *extra]


def edit(file: str, text: str) -> Callable[[Path], Path]:
    """A sphere folder with ``file`` replaced by ``text``."""
    def build(root: Path) -> Path:
        folder = sphere_folder(root)
        (folder / file).write_text(text)
        return folder
    return build


def gt(build_folder):
    return lambda root: folder_args(build_folder(root), "light=gt", *WOODHAM)


def _lights_in_plane(n):
    angles = np.linspace(0, np.pi, n, endpoint=False) + 0.3
    return np.stack([np.cos(angles), np.zeros(n), np.sin(angles)], -1)


def _nearly_coplanar(n):
    angles = np.linspace(0.2, 2.9, n)
    return np.stack([np.cos(angles), 0.02 * np.cos(3 * angles), np.sin(angles)], -1) / 1.0002


def _clip_share(images, share):
    """Scale so that about ``share`` of the object's values reach 1, then clip."""
    level = np.quantile(images[images > 0], 1 - share)
    return np.clip(images / level, 0, 1)


def _one_image(images, value):
    images = images.copy()
    images[0] = value
    return images


def _rows(text_rows):
    return "\n".join(text_rows) + "\n"


CASES = [
    # -- options ------------------------------------------------------------------------------
    Case("folder without root", "`subject=folder` and no `subject.root`",
         lambda root: ["subject=folder", *WOODHAM], 2, "subject.root=…"),
    Case("noise not a number", "`noise=abc`",
         lambda root: ["subject=lambertian", "light=gt", "noise=abc", *WOODHAM], 2, "noise must be a number"),
    Case("noise negative", "`noise=-1`",
         lambda root: ["subject=lambertian", "light=gt", "noise=-1", *WOODHAM], 2, "noise"),
    Case("threads zero", "`threads=0`",
         lambda root: ["subject=lambertian", "light=gt", "threads=0", *WOODHAM], 2, "threads must be"),
    Case("unknown device", "`device=gpu`",
         lambda root: ["subject=lambertian", "light=gt", "device=gpu", *WOODHAM], 2, "device must be"),
    Case("refine without unps", "`light=refine method=woodham`",
         lambda root: ["subject=lambertian", "light=refine", *WOODHAM], 2, "needs method=unps"),
    Case("refine neither true, false nor auto", "`light.refine=maybe`",
         lambda root: ["subject=lambertian", "light.refine=maybe", *WOODHAM], 2,
         "light.refine=maybe: expected true, false or auto"),
    Case("facet factor zero", "`interreflection.downsample=0` with `method=unps`",
         lambda root: ["subject=lambertian", "light=gt", "interreflection.downsample=0"], 2,
         "interreflection.downsample"),
    Case("unknown encoding", "`subject.encoding=xyz`",
         lambda root: folder_args(sphere_folder(root), "subject.encoding=xyz", "light=gt", *WOODHAM), 2,
         "encoding must be"),
    Case("unknown quantization", "`subject.quantization=xyz`",
         lambda root: folder_args(sphere_folder(root), "subject.quantization=xyz", "light=gt", *WOODHAM), 2,
         "quantization"),
    Case("drop out of range", "`subject.drop=[99]` on 12 images",
         lambda root: folder_args(sphere_folder(root), "subject.drop=[99]", "light=gt", *WOODHAM), 2, "99"),
    Case("missing light checkpoint", "`light=estimated light.checkpoint=/nowhere.ckpt`",
         lambda root: folder_args(sphere_folder(root), "light=estimated", "light.checkpoint=/nowhere.ckpt",
                                  *WOODHAM), 2, "/nowhere.ckpt"),
    Case("unknown light stage", "`light=estimated light.stages=[mirror]`",
         lambda root: ["subject=lambertian", "light=estimated", "light.stages=[mirror]", *WOODHAM], 2,
         "light.stages"),
    Case("light stage without settings", "`light=selfcal light.selfcal=null`",
         lambda root: ["subject=lambertian", "light=selfcal", "light.selfcal=null", *WOODHAM], 2,
         "light.selfcal"),
    Case("reversal force neither true nor false", "`light=estimated light.reversal.force=ture`",
         lambda root: ["subject=lambertian", "light=estimated", "light.reversal.force=ture", *WOODHAM], 2,
         "light.reversal.force"),
    Case("framing outside (0, 1]", "`light=estimated light.framings=[1.0,1.5]`",
         lambda root: ["subject=lambertian", "light=estimated", "light.framings=[1.0,1.5]", *WOODHAM], 2,
         "light.framings"),
    Case("seed not a whole number", "`seed=abc`",
         lambda root: ["subject=lambertian", "light=gt", "seed=abc", *WOODHAM], 2, "seed must be"),
    Case("no fit steps", "`preset.steps=0` with `method=unps`",
         lambda root: ["subject=lambertian", "light=gt", "preset.steps=0"], 2, "preset.steps"),
    Case("negative fit steps", "`preset.steps=-5` with `method=unps`",
         lambda root: ["subject=lambertian", "light=gt", "preset.steps=-5"], 2, "preset.steps"),
    Case("fractional fit steps", "`preset.steps=2.5` with `method=unps`",
         lambda root: ["subject=lambertian", "light=gt", "preset.steps=2.5"], 2, "preset.steps"),
    Case("learning rate zero", "`preset.lr=0` with `method=unps`",
         lambda root: ["subject=lambertian", "light=gt", "preset.lr=0"], 2, "preset.lr"),
    Case("pixel share above 1", "`preset.pixel_keep=1.5` with `method=unps`",
         lambda root: ["subject=lambertian", "light=gt", "preset.pixel_keep=1.5"], 2, "preset.pixel_keep"),
    Case("no reflectance branch", "`preset.reflectance_branch=0` with `method=unps`",
         lambda root: ["subject=lambertian", "light=gt", "preset.reflectance_branch=0"], 2,
         "preset.reflectance_branch"),
    Case("feature scale width not whole", "`preset.feature_scale_width=48.5` with `method=unps`",
         lambda root: ["subject=lambertian", "light=gt", "preset.feature_scale_width=48.5"], 2,
         "preset.feature_scale_width"),
    Case("batch norm not a switch", "`preset.batch_norm=maybe` with `method=unps`",
         lambda root: ["subject=lambertian", "light=gt", "preset.batch_norm=maybe"], 2, "preset.batch_norm"),
    Case("unknown initialisation", "`preset.init=woodham` with `method=unps`",
         lambda root: ["subject=lambertian", "light=gt", "preset.init=woodham"], 2, "preset.init"),
    Case("unknown option of a group", "`preset=nonexistent`",
         lambda root: ["subject=lambertian", "light=gt", "preset=nonexistent", *WOODHAM], 2,
         "preset/nonexistent"),
    Case("misspelt method", "`method=typo`",
         lambda root: ["subject=lambertian", "light=gt", "method=typo"], 2, "method/typo"),
    Case("unknown key", "`light.nokey=3`",
         lambda root: ["subject=lambertian", "light=gt", "light.nokey=3", *WOODHAM], 2, "light.nokey"),
    Case("value Hydra cannot parse", "`noise=[0.1`",
         lambda root: ["subject=lambertian", "light=gt", "noise=[0.1", *WOODHAM], 2, "noise=[0.1"),
    Case("run folder is a file", "`hydra.run.dir` naming an existing file",
         lambda root: ["subject=lambertian", "light=gt", *WOODHAM, f"hydra.run.dir={_a_file(root)}"], 2,
         "cannot write"),
    Case("run folder inside a file", "`hydra.run.dir` below an existing file",
         lambda root: ["subject=lambertian", "light=gt", *WOODHAM, f"hydra.run.dir={_a_file(root)}/run"],
         2, "cannot write"),
    # -- files --------------------------------------------------------------------------------
    Case("folder under ~", "`subject.root=~/…` unquoted, as bash passes it (works)",
         lambda root: ["subject=folder", f"subject.root=~/{sphere_folder(root).relative_to(root.parent)}",
                       "light=gt", *WOODHAM], 0, ""),
    Case("no mask file", "a folder without `mask.png` (works: the mask is found from the images)",
         lambda root: _without_mask(root), 0, ""),
    Case("named mask missing", "`subject.mask=other.png` not in the folder",
         lambda root: folder_args(sphere_folder(root), "subject.mask=other.png", "light=gt", *WOODHAM), 2,
         "mask file not found"),
    Case("root not a folder", "`subject.root` that does not exist",
         lambda root: folder_args(root / "nowhere", *WOODHAM), 2, "nowhere: not a folder"),
    Case("no images", "a folder without image files",
         lambda root: folder_args(root, *WOODHAM), 2, "no image files"),
    Case("corrupt image", "a `.png` that is not an image",
         lambda root: folder_args(edit("002.png", "not a picture")(root), "light=gt", *WOODHAM),
         2, "002.png"),
    Case("mask wrong size", "a mask of another size than the images",
         lambda root: _mask_of(root, np.full((20, 20), 255, np.uint8)), 2, "mask.png"),
    Case("mask empty", "an all-black mask",
         lambda root: _mask_of(root, np.zeros((32, 32), np.uint8)), 2, "mask is empty"),
    Case("directions row count", "`light_directions.txt` with 11 rows for 12 images",
         gt(edit("light_directions.txt", _rows(["0 0 1"] * 11))), 2, "light_directions.txt"),
    Case("directions not numbers", "`light_directions.txt` with a word in it",
         gt(edit("light_directions.txt", _rows(["0 0 1"] * 11 + ["up 0 1"]))), 2, "light_directions.txt"),
    Case("direction zero", "a `0 0 0` row in `light_directions.txt`",
         gt(edit("light_directions.txt", _rows(["0 0.5 1"] * 11 + ["0 0 0"]))), 2, "light_directions.txt"),
    Case("direction NaN", "a `nan` in `light_directions.txt`",
         gt(edit("light_directions.txt", _rows(["0 0.5 1"] * 11 + ["nan 0 1"]))), 2, "light_directions.txt"),
    Case("intensities row count", "`light_intensities.txt` with 3 rows for 12 images",
         gt(edit("light_intensities.txt", _rows(["1 1 1"] * 3))), 2, "light_intensities.txt"),
    Case("intensity zero", "a `0 0 0` row in `light_intensities.txt`",
         gt(edit("light_intensities.txt", _rows(["1 1 1"] * 11 + ["0 0 0"]))), 2, "light_intensities.txt"),
    Case("filenames lists a missing file", "`filenames.txt` naming a file that is not there",
         gt(edit("filenames.txt", _rows([f"{i:03d}.png" for i in range(1, 12)] + ["missing.png"]))), 2,
         "missing.png"),
    Case("uncalibrated with light=gt", "no `light_directions.txt` and `light=gt`",
         lambda root: _without_lights(root), 2, "light"),
    # -- inputs that can be read but not solved -------------------------------------------------
    Case("two images", "2 images", lambda root: folder_args(sphere_folder(root, 2), "light=gt", *WOODHAM), 2,
         "at least 3 images"),
    Case("four images", "4 images (works, with a warning)",
         lambda root: folder_args(sphere_folder(root, 4), "light=gt", *WOODHAM), 0, "only 4 images"),
    Case("identical lights", "every light the same",
         lambda root: folder_args(sphere_folder(root, lights=np.tile([0.3, 0.2, 0.93], (12, 1))),
                                  "light=gt", *WOODHAM), 2, "do not span 3D"),
    Case("coplanar lights", "all lights in one plane through the object",
         lambda root: folder_args(sphere_folder(root, lights=_lights_in_plane(12)), "light=gt", *WOODHAM), 2,
         "do not span 3D"),
    Case("nearly coplanar lights", "lights within ±1° of one plane (works, with a warning)",
         lambda root: folder_args(sphere_folder(root, lights=_nearly_coplanar(12)), "light=gt", *WOODHAM), 0,
         "nearly coplanar"),
    Case("all black", "every image black", lambda root: folder_args(
        sphere_folder(root, transform=lambda x: 0 * x), "light=gt", *WOODHAM), 2, "black on the object"),
    Case("all black, rpca", "every image black, `method=rpca`", lambda root: folder_args(
        sphere_folder(root, transform=lambda x: 0 * x), "light=gt", "method=rpca"), 2, "black on the object"),
    Case("all clipped", "every pixel saturated", lambda root: folder_args(
        sphere_folder(root, transform=lambda x: np.ones_like(x)), "light=gt", *WOODHAM), 2, "clipped"),
    Case("over-exposed", "a fifth of the values clipped (works, with a warning)", lambda root: folder_args(
        sphere_folder(root, transform=lambda x: _clip_share(x, 0.2)), "light=gt", *WOODHAM), 0, "clipped"),
    Case("one black image", "one image black (left out, with a warning)", lambda root: folder_args(
        sphere_folder(root, transform=lambda x: _one_image(x, 0.0)), "light=gt", *WOODHAM), 0,
        "is black on the whole object"),
    Case("one clipped image", "one image white (left out, with a warning)", lambda root: folder_args(
        sphere_folder(root, transform=lambda x: _one_image(x, x.max())), "light=gt", *WOODHAM), 0,
        "is clipped on the whole object"),
    Case("selfcal with 3 images", "`light=selfcal` on 3 images",
         lambda root: folder_args(sphere_folder(root, 3), "light=selfcal", *WOODHAM), 2,
         "self-calibration needs at least 4 images"),
]


def _mask_of(root: Path, mask: np.ndarray) -> list[str]:
    import cv2

    folder = sphere_folder(root)
    cv2.imwrite(str(folder / "mask.png"), mask)
    return folder_args(folder, "light=gt", *WOODHAM)


def _a_file(root: Path) -> Path:
    (root / "taken").write_text("not a folder\n")
    return root / "taken"


def _without_mask(root: Path) -> list[str]:
    folder = sphere_folder(root)
    (folder / "mask.png").unlink()
    return folder_args(folder, "light=gt", *WOODHAM)


def _without_lights(root: Path) -> list[str]:
    folder = sphere_folder(root)
    (folder / "light_directions.txt").unlink()
    return folder_args(folder, "light=gt", *WOODHAM)


@dataclass(frozen=True)
class Outcome:
    case: Case
    code: int
    message: str          # the last line on stderr (errors) or the matching warning
    traceback: bool
    wrote_metrics: bool
    left_run_folder: bool

    @property
    def passed(self) -> bool:
        return (self.code == self.case.code and self.case.culprit in self.message and not self.traceback
                and self.wrote_metrics == (self.code == 0) and not self.left_run_folder)


def run(case: Case) -> Outcome:
    """Build the case's input in a scratch folder and run the command line on it."""
    with tempfile.TemporaryDirectory(prefix="unps-bad-") as scratch:
        root = Path(scratch)
        (root / "input").mkdir()
        args = case.build(root / "input")
        out = root / "run"
        if not any(a.startswith("hydra.run.dir=") for a in args):
            args = [*args, f"hydra.run.dir={out}"]
        done = subprocess.run([sys.executable, "-m", "unps.fit", *args], cwd=root, capture_output=True,
                              text=True, timeout=600, env={**os.environ, "HOME": str(root)})
        text = done.stdout + done.stderr
        metrics = out / "metrics.json"
        if done.returncode == 0 and metrics.is_file():
            warnings = json.loads(metrics.read_text()).get("warnings", [])
            message = next((w for w in warnings if case.culprit in w), "; ".join(warnings))
        else:
            lines = [line for line in done.stderr.splitlines() if line.strip()]
            message = lines[-1] if lines else ""
        left = out.exists() and done.returncode != 0          # bad input leaves no run folder
        return Outcome(case, done.returncode, message, "Traceback" in text, metrics.is_file(), left)


def table(outcomes: list[Outcome]) -> str:
    rows = ["| case | input | exit | message (last stderr line, or the warning in metrics.json) |",
            "|---|---|---|---|"]
    for o in outcomes:
        message = o.message.split("] - ", 1)[-1].replace("|", "\\|")
        rows.append(f"| {o.case.name} | {o.case.what} | {o.code} | {message} |")
    return "\n".join(rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--only", default="", help="run only the cases whose name contains this")
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args()
    cases = [c for c in CASES if args.only in c.name]
    with ThreadPoolExecutor(args.jobs) as pool:
        outcomes = list(pool.map(run, cases))
    for o in outcomes:
        print(f"{'ok  ' if o.passed else 'FAIL'} {o.case.name}: exit {o.code}: {o.message}")
    if not args.only:
        DOCS.write_text(
            "# Bad input and what unps says\n\nGenerated by `python experiments/bad_input/cases.py` "
            "(every case is also a test, `tests/test_cli_bad_input.py`). Each row is one run of "
            "`python -m unps.fit` on a 32×32 rendered sphere broken one way. Errors exit with status 2, "
            "print one line on stderr and leave no run folder; inputs that can still be solved exit 0 and "
            "record the warning in `metrics.json`. No case prints a traceback. What the warnings "
            f"mean: [own_photos.md](own_photos.md).\n\n{table(outcomes)}\n")
        print(f"wrote {DOCS}")
    if not all(o.passed for o in outcomes):
        sys.exit(1)


if __name__ == "__main__":
    main()

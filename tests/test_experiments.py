import dataclasses
import doctest
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import nbformat
import numpy as np
import pytest
from hydra import compose, initialize_config_module
from hydra._internal.core_plugins.basic_sweeper import BasicSweeper
from hydra.core.override_parser.overrides_parser import OverridesParser

from conftest import SHARED_DATA, diligent_object, load_script
from unps.data.analytic import dome_lights, height_field, render_lambertian
from unps.data.diligent import find_diligent_object, read_diligent, read_diligent_object, read_folder
from unps.data.lights import Lights
from unps.data.subject import Subject
from unps.data.writer import write_diligent
from unps.errors import InputError
from unps.geometry import outline_distance
from unps.fit import fit
from unps.io.images import write_png8
from unps.plan import expand, plan, print_plan
from unps.report import report

EXPERIMENTS = sorted(p.stem for p in (Path(__file__).parents[1] / "unps" / "conf" / "experiment").glob("*.yaml"))
NOTEBOOK = Path(__file__).parents[1] / "notebooks" / "01_quickstart.ipynb"


def hydra_config(*overrides):
    with initialize_config_module(config_module="unps.conf", version_base="1.3"):
        return compose("fit", overrides=list(overrides), return_hydra_config=True)


def test_every_study_has_an_experiment():
    assert EXPERIMENTS == ["baselines", "facets", "light_stats", "noise", "rose", "table1"]


@pytest.mark.parametrize("name", EXPERIMENTS)
def test_experiment_composes_every_job(name):
    cfg = hydra_config(f"experiment={name}")
    assert cfg.study == name and cfg.hydra.sweep.dir == f"multirun/{name}"
    _, jobs = plan([f"experiment={name}"])   # composes each job's config
    sizes = [len(str(v).split(",")) for v in cfg.hydra.sweeper.params.values()]
    assert len(jobs) == int(np.prod(sizes)) > 0
    assert len({folder for _, folder in jobs}) == len(jobs)   # no two jobs share a run folder


def test_study_settings():
    facets = hydra_config("experiment=facets", "interreflection=nayar_x8")
    assert facets.light.name == "gt" and facets.interreflection.downsample == 8
    assert hydra_config("experiment=light_stats").method.name == "woodham"
    table1 = hydra_config("experiment=table1")
    assert set(table1.hydra.sweeper.params.light.split(",")) == {"gt", "estimated", "refine"}


@pytest.mark.parametrize("launcher, target", [("slurm", "SlurmLauncher"), ("local", "JoblibLauncher")])
def test_launchers_compose(launcher, target):
    cfg = hydra_config("experiment=noise", f"hydra/launcher={launcher}")
    assert cfg.hydra.launcher._target_.endswith(target)
    if launcher == "slurm":
        assert cfg.hydra.launcher.submitit_folder.startswith("multirun/noise")


def test_dry_run_prints_every_job(capsys):
    print_plan(["experiment=noise", "hydra/launcher=slurm", "hydra.launcher.partition=gpu"])
    out = capsys.readouterr().out
    assert out.startswith("dry run: 24 jobs, launcher SlurmLauncher (partition=gpu")
    assert "#23 subject=BrokenPot noise=0.2 experiment=noise" in out
    assert "→  multirun/noise/noise=0.2,subject=BrokenPot" in out


def test_dry_run_refuses_a_job_that_does_not_compose():
    with pytest.raises(InputError, match="job subject=Nowhere does not compose"):
        plan(["subject=Face,Nowhere"])


@pytest.mark.parametrize("params, overrides", [
    ({"subject": "Vase,Face", "noise": "0,0.1"}, []),
    ({"subject": "Vase,Face"}, ["subject=Tablet1", "seed=1,2", "method=woodham"]),
])
def test_expand_matches_hydras_basic_sweeper(params, overrides):
    parsed = OverridesParser.create().parse_overrides([f"{k}={v}" for k, v in params.items()] + overrides)
    [hydras] = BasicSweeper.split_arguments(parsed, None)
    assert expand(params, overrides) == hydras


def test_diligent_objects_by_name(tmp_path):
    write_diligent(render_lambertian(size=16, n_lights=4), tmp_path / "pmsData_crop" / "catPNG")
    assert find_diligent_object(tmp_path, "cat") == tmp_path / "pmsData_crop" / "catPNG"
    write_diligent(render_lambertian(size=16, n_lights=4), tmp_path / "pmsData" / "catPNG")
    assert find_diligent_object(tmp_path, "cat") == tmp_path / "pmsData" / "catPNG"   # the original first
    with pytest.raises(InputError, match="no DiLiGenT object 'pot1'"):
        find_diligent_object(tmp_path, "pot1")
    with pytest.raises(InputError, match="DiLiGenT not found.*UNPS_DILIGENT_DIR"):
        find_diligent_object(tmp_path / "nowhere", "cat")


def test_diligent_crops_are_read_as_truncated_and_originals_as_rounded(tmp_path):
    subject = render_lambertian(size=16, n_lights=4)
    for layout in ("pmsData_crop", "pmsData"):
        write_diligent(subject, tmp_path / layout / "catPNG")
        folder = tmp_path / layout / "catPNG"
        expected = "floor" if layout == "pmsData_crop" else "round"
        np.testing.assert_array_equal(read_diligent_object(tmp_path, "cat").images,
                                      read_diligent(folder, quantization=expected).images)
        assert not np.array_equal(read_diligent(folder, quantization="round").images,
                                  read_diligent(folder, quantization="floor").images)
        np.testing.assert_array_equal(read_diligent(folder, quantization="auto").images,   # 16-bit
                                      read_diligent(folder, quantization="round").images)
    with pytest.raises(InputError, match="quantization must be round or floor.*'nearest'"):
        read_diligent_object(tmp_path, "cat", quantization="nearest")


def test_subject_by_name_runs_end_to_end(tmp_path):
    data = tmp_path / "DiLiGenT"
    write_diligent(render_lambertian(size=24, n_lights=12, seed=2), data / "pmsData" / "ballPNG")
    with initialize_config_module(config_module="unps.conf", version_base="1.3"):
        cfg = compose("fit", overrides=["subject=ball", f"paths.diligent_dir={data}", "method=woodham",
                                        "light=estimated", f"paths.output_dir={tmp_path / 'run'}"])
    metrics = fit(cfg)
    assert metrics["subject"] == "ball" and metrics["study"] is None
    run = tmp_path / "run"
    assert {"normals_gt.png", "error.npy", "lights_gt.txt"} <= {p.name for p in run.iterdir()}
    assert np.loadtxt(run / "lights_gt.txt").shape == (12, 6)
    error = np.load(run / "error.npy")
    assert np.nanmean(error.astype(np.float64)) == pytest.approx(metrics["normal_mae"], abs=0.05)


# --------------------------------------------------------------------------- the aggregator


def fake_run(sweep: Path, name: str, files: bool = False, **metrics) -> Path:
    """A run folder as unps.fit leaves it, with made-up metrics (and pictures if ``files``)."""
    folder = sweep / name
    (folder / ".hydra").mkdir(parents=True)
    defaults = {"study": None, "seed": 0, "method": "unps", "light": "estimated", "noise": 0.0,
                "preset": "fast", "n_images": 100, "resolution": [8, 8], "runtime_s": 10.0,
                "normal_median": 1.0, "acc_30": 0.9, "light_dir_mae": 5.0, "light_int_err": 0.1,
                "interreflection": True, "facet_downsample": 4, "facets": 100}
    (folder / "metrics.json").write_text(json.dumps({**defaults, **metrics}))
    if files:
        mask = np.ones((8, 8), bool)
        write_png8(folder / "normals.png", np.full((8, 8, 3), 128, np.uint8))
        write_png8(folder / "normals_gt.png", np.full((8, 8, 3), 100, np.uint8))
        np.save(folder / "error.npy", np.where(mask, 3.0, np.nan).astype(np.float16))
        write_png8(folder / "reflectance.png", np.full((8, 48, 3), 90, np.uint8))
    return folder


def test_table1_report(tmp_path):
    sweep = tmp_path / "table1"
    for subject, gt, est, refine in (("Vase", 10.0, 12.0, 11.0), ("cat", 6.0, 9.5, 7.0)):
        for light, value in (("gt", gt), ("estimated", est), ("refine", refine)):
            fake_run(sweep, f"light={light},subject={subject}", study="table1", subject=subject,
                     light=light, normal_mae=value)
    (sweep / "light=gt,subject=Face" / ".hydra").mkdir(parents=True)   # started, never finished
    text = report(sweep).read_text()
    assert "| Vase | 10.00 | 12.00 | +2.00 | 11.00 | 5.00 → 5.00 | 16.40 | 19.91 | +3.51 |" in text
    assert "| cat | 6.00 | 9.50 | +3.50 | 7.00 | 5.00 → 5.00 | — | 7.91 | — |" in text
    assert "| **average, all** | 8.00 | 10.75 | +2.75 | 9.00 |  | — | 13.91 | — |" in text
    assert "average, the paper's six" not in text   # only two of them ran
    assert "**1 unfinished runs** (no metrics.json): `light=gt,subject=Face`" in text
    assert (sweep / "report" / "table1.png").stat().st_size > 0


def test_noise_report_and_it_is_reproducible(tmp_path):
    sweep = tmp_path / "noise"
    for subject, base in (("Vase", 10.0), ("Face", 4.0)):
        for sigma in (0.0, 0.1):
            fake_run(sweep, f"noise={sigma},subject={subject}", study="noise", subject=subject,
                     noise=sigma, normal_mae=base + 20 * sigma)
    first = report(sweep, tmp_path / "a")
    assert "| subject | σ = 0 | σ = 0.1 |" in first.read_text()
    assert "| Vase | 10.00 | 12.00 |" in first.read_text()
    assert "| **average** | 7.00 | 9.00 |" in first.read_text()
    assert "Direction MAE (°) of the lights used" in first.read_text()
    assert "| Face | 5.00 | 5.00 |" in first.read_text()          # the light errors
    second = report(sweep, tmp_path / "b")
    for name in ("results.md", "noise.png"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()
    assert second.read_text() == first.read_text()


def test_facets_report(tmp_path):
    sweep = tmp_path / "facets"
    for setting, factor, facets, value in (("nayar_x2", 2, 400, 9.0), ("nayar", 4, 100, 8.0),
                                           ("off", 4, 0, 10.0)):
        fake_run(sweep, f"interreflection={setting},subject=Vase", study="facets", subject="Vase",
                 light="gt", interreflection=setting != "off", facet_downsample=factor, facets=facets,
                 normal_mae=value, runtime_s=100.0 * facets / 100 + 50)
    text = report(sweep).read_text()
    assert "| subject | ×2 | ×4 | off |" in text
    assert "| Vase | 9.00 | 8.00 | 10.00 |" in text
    assert "| Vase | 450 | 150 | 50 |" in text        # run time
    assert "| Vase | 400 | 100 | 1280 |" in text       # facets, and the paper's count


def test_light_stats_report_plots_the_components(tmp_path):
    sweep = tmp_path / "light_stats"
    folder = fake_run(sweep, "subject=Sphere", study="light_stats", subject="Sphere", method="woodham",
                      normal_mae=5.0, light_dir_mae=4.25, light_int_err=0.05)
    true = np.c_[np.eye(3), np.ones((3, 3))]
    np.savetxt(folder / "lights_gt.txt", true)
    np.savetxt(folder / "lights.txt", true)
    text = report(sweep).read_text()
    assert "| Sphere | 100 | 4.25 | 0.050 |" in text and "| Sphere (paper) | — | 6.31 | — |" in text
    assert (sweep / "report" / "lights_Sphere.png").is_file()


def test_baselines_and_rose_reports_draw_their_pictures(tmp_path):
    sweep = tmp_path / "baselines"
    for method, value in (("woodham", 20.0), ("rpca", 18.0), ("nayar", 19.0), ("unps", 15.0)):
        fake_run(sweep, f"method={method},subject=Vase", files=True, study="baselines", subject="Vase",
                 method=method, normal_mae=value)
    text = report(sweep).read_text()
    assert "| Vase | 20.00 | 18.00 | 19.00 | 15.00 |" in text
    assert {"grid_Vase.png", "reflectance_maps.png"} <= {p.name for p in (sweep / "report").iterdir()}

    rose = tmp_path / "rose"
    fake_run(rose, "light=gt,subject=Rose", files=True, study="rose", subject="Rose", light="gt",
             normal_mae=40.0)
    assert "| Rose | gt | 40.00 | 1.00 | 90.0 % |" in report(rose).read_text()
    assert (rose / "report" / "rose.png").is_file()


def test_report_refuses_what_it_cannot_read(tmp_path):
    with pytest.raises(InputError, match="no finished run"):
        report(tmp_path)
    fake_run(tmp_path, "a", study="noise", subject="Vase", normal_mae=1.0)
    fake_run(tmp_path, "b", study="table1", subject="Vase", normal_mae=1.0)
    with pytest.raises(InputError, match="runs of several studies"):
        report(tmp_path)
    with pytest.raises(InputError, match="not a folder"):
        report(tmp_path / "nowhere")


def test_any_other_sweep_gets_one_row_per_run(tmp_path):
    fake_run(tmp_path, "method=woodham", subject="Vase", method="woodham", normal_mae=20.0)
    fake_run(tmp_path, "method=rpca", subject="Vase", method="rpca", normal_mae=18.5)
    text = report(tmp_path).read_text()
    assert "| method | normal MAE (°) | light MAE (°) | time (s) | folder |" in text
    assert "| rpca | 18.50 | 5.00 | 10.0 | method=rpca |" in text


# --------------------------------------------------------------------------- the notebook


def test_notebook_is_committed_without_outputs():
    notebook = nbformat.read(NOTEBOOK, as_version=4)
    code = [c for c in notebook.cells if c.cell_type == "code"]
    assert all(not c.outputs and c.execution_count is None for c in code)
    assert "parameters" in code[0].metadata.get("tags", [])


@pytest.mark.slow
def test_notebook_runs_at_tiny_size(tmp_path):
    from nbclient import NotebookClient

    notebook = nbformat.read(NOTEBOOK, as_version=4)
    notebook.cells[1].source = ('SUBJECT = "lambertian"\nSTEPS = 10\n'
                                'OVERRIDES = ["subject.size=24", "subject.n_lights=12"]')
    NotebookClient(notebook, timeout=300, kernel_name="python3",
                   resources={"metadata": {"path": str(tmp_path)}}).execute()
    printed = "".join(o.get("text", "") for c in notebook.cells if c.cell_type == "code" for o in c.outputs)
    assert "lambertian-sphere: 12 images of 24×24 pixels" in printed
    assert "fit: normal MAE" in printed
    images = [o for c in notebook.cells if c.cell_type == "code" for o in c.outputs
              if "image/png" in o.get("data", {})]
    assert len(images) >= 5


@pytest.mark.parametrize("script", sorted(str(p.relative_to(Path(__file__).parents[1]))
                                          for p in (Path(__file__).parents[1] / "experiments").glob("*/*.py")))
def test_experiment_scripts_import(script):
    """Every experiment script loads against the package as it is now (its imports resolve)."""
    load_script(Path(script).stem, script)

def test_nir_benchmark_reads_one_row_per_seed_and_averages(tmp_path):
    """Finished rows are read, not refitted: seed 0 in <row>/, seed k in <row>-seed<k>/."""
    benchmark = load_script("nir_benchmark", "experiments/neural_inverse_rendering/benchmark.py")
    for folder, mae, seed in [("ball-gt-unps-fast", 2.0, 0), ("ball-gt-unps-fast-seed3", 3.0, 3)]:
        (tmp_path / folder / ".hydra").mkdir(parents=True)
        (tmp_path / folder / "metrics.json").write_text(json.dumps({"normal_mae": mae}))
        made = benchmark.runs.fit_settings(["subject=ball", f"seed={seed}"])   # as Hydra records it
        (tmp_path / folder / ".hydra" / "config.yaml").write_text(json.dumps(made))
    fits = benchmark.unps_rows(tmp_path, "ball-gt-unps-fast", ["subject=ball"], [0, 3])
    assert [f["normal_mae"] for f in fits] == [2.0, 3.0]
    assert benchmark.mae(fits) == "2.50 (2.00 / 3.00)"
    assert benchmark.mae(fits[:1]) == "2.00"
    (tmp_path / "ball-gt-unps-fast" / ".hydra" / "overrides.yaml").write_text("- subject=ball\n- seed=0\n")
    assert benchmark.unps_rows(tmp_path, "ball-gt-unps-fast", ["subject=ball"], [0])[0]["normal_mae"] == 2.0
    with pytest.raises(ValueError, match=r"lacks \['preset.input_noise_var=0.3'\] and has \[\]"):
        benchmark.unps_rows(tmp_path, "ball-gt-unps-fast", ["subject=ball", "preset.input_noise_var=0.3"], [0])


def test_nir_benchmark_fits_a_stale_row_afresh(tmp_path, monkeypatch):
    """A finished or stopped row made with other settings is fitted again from nothing: the
    checkpoint it left (which unps.fit would refuse as another run's) is gone before the fit
    starts."""
    benchmark = load_script("nir_benchmark_stale", "experiments/neural_inverse_rendering/benchmark.py")
    row = tmp_path / "ball-selfcal-unps-fast"
    (row / ".hydra").mkdir(parents=True)
    (row / "checkpoints").mkdir()
    (row / "checkpoints" / "last.ckpt").write_text("a checkpoint of the old settings")
    (row / "metrics.json").write_text(json.dumps({"normal_mae": 9.0}))
    old = benchmark.runs.fit_settings(["subject=ball", "seed=1"])
    (row / ".hydra" / "config.yaml").write_text(json.dumps(old))
    seen = []

    def fit(command, **kwargs):
        seen.append(sorted(p.name for p in row.rglob("*")))
        (row / "metrics.json").write_text(json.dumps({"normal_mae": 2.0}))
        return subprocess.CompletedProcess(command, 0, "", "")

    monkeypatch.setattr(benchmark.subprocess, "run", fit)
    assert benchmark.run(row, "subject=ball", "seed=0")["normal_mae"] == 2.0
    assert seen == [[]]
    (row / "metrics.json").unlink()   # stopped part way under other settings: not resumed either
    (row / ".hydra").mkdir()
    (row / ".hydra" / "config.yaml").write_text(json.dumps(old))
    (row / "checkpoints").mkdir()
    (row / "checkpoints" / "last.ckpt").write_text("a checkpoint of the old settings")
    assert benchmark.run(row, "subject=ball", "seed=0")["normal_mae"] == 2.0
    assert seen == [[], []]
    with benchmark.runs.held(row):   # the mark of a run under way stays; all else goes
        (row / "normals.png").write_text("a picture")
        benchmark.runs.discard(row)
        assert [p.name for p in row.iterdir()] == [benchmark.runs.MARK]


def test_a_row_whose_read_out_settings_changed_is_read_out_again_from_its_checkpoint(tmp_path, monkeypatch):
    """Where a row's fit differs from the one asked for only in the preset's read-out settings, its
    checkpoint stays (unps.fit resumes from it at its last step and reads the normals out again) and
    its metrics go; any other difference still fits it from nothing."""
    benchmark = load_script("nir_benchmark_read_out", "experiments/neural_inverse_rendering/benchmark.py")
    row = tmp_path / "ball-gt-unps-fast"
    old = benchmark.runs.fit_settings(["subject=ball", "preset.refine_pixels=false", "preset.continue_held=0"])

    def made_with(settings: dict) -> None:
        (row / ".hydra").mkdir(parents=True, exist_ok=True)
        (row / ".hydra" / "config.yaml").write_text(json.dumps(settings))
        (row / "checkpoints").mkdir(exist_ok=True)
        (row / "checkpoints" / "last.ckpt").write_text("the fit's last checkpoint")
        (row / "metrics.json").write_text(json.dumps({"normal_mae": 9.0}))

    made_with(old)
    now = benchmark.runs.fit_settings(["subject=ball"])
    assert benchmark.runs.steps_kept(row, now)
    assert not benchmark.runs.steps_kept(row, benchmark.runs.fit_settings(["subject=ball", "preset.lr=1e-3"]))
    seen = []

    def fit(command, **kwargs):
        seen.append(sorted(p.relative_to(row).as_posix() for p in row.rglob("*")))
        (row / "metrics.json").write_text(json.dumps({"normal_mae": 2.0}))
        return subprocess.CompletedProcess(command, 0, "", "")

    monkeypatch.setattr(benchmark.subprocess, "run", fit)
    assert benchmark.run(row, "subject=ball")["normal_mae"] == 2.0
    assert seen == [[".hydra", ".hydra/config.yaml", "checkpoints", "checkpoints/last.ckpt"]]
    made_with(benchmark.runs.fit_settings(["subject=ball", "preset.refine_pixels=false", "preset.steps=300"]))
    assert benchmark.run(row, "subject=ball")["normal_mae"] == 2.0
    assert seen[1] == []
    made_with(old)
    (row / "checkpoints" / "last.ckpt").unlink()    # nothing to resume from: made again from nothing
    assert not benchmark.runs.steps_kept(row, now)


def test_nir_benchmark_names_a_missing_diligent_folder(tmp_path):
    """--diligent points the benchmark at DiLiGenT; a folder that is not there is named, nothing run."""
    missing = tmp_path / "no-diligent"
    done = subprocess.run([sys.executable, "experiments/neural_inverse_rendering/benchmark.py", "--only",
                           "diligent", "--diligent", str(missing), "--out", str(tmp_path / "runs")],
                          capture_output=True, text=True, cwd=Path(__file__).parents[1])
    assert done.returncode == 1
    assert f"{missing}: DiLiGenT not found (give --diligent" in done.stderr
    assert not (tmp_path / "runs").exists()


def test_light_benchmark_normals_reads_finished_rows_refuses_mixed_settings_and_keeps_light_sets_apart(
        tmp_path):
    normals = load_script("lb_normals", "experiments/light_benchmark/normals.py")
    obj = normals.scenes.OBJECTS[0]
    run = tmp_path / f"{obj.name}-rpca"
    (run / ".hydra").mkdir(parents=True)
    (run / "metrics.json").write_text(json.dumps({"normal_mae": 4.5}))
    overrides = ["subject=folder", f"subject.root={tmp_path / 'nowhere'}", f"subject.name={obj.name}",
                 f"subject.quantization={normals.scenes.quantization(obj.storage)}", "light=gt", "method=rpca"]
    made = normals.runs.fit_settings(overrides)
    assert made["method"]["name"] == "rpca" and made["seed"] == 0 and "threads" not in made
    (run / ".hydra" / "config.yaml").write_text(json.dumps({**made, "threads": 1, "paths": {}}))
    assert normals.run_row(tmp_path / "nowhere", obj, "rpca", "gt", [], tmp_path)["normal_mae"] == 4.5
    assert normals.runs.stale_run(run, made) is None
    assert normals.runs.stale_run(run, normals.runs.fit_settings([*overrides, "seed=1", "preset.steps=300"])) == (
        "made with other settings (preset.steps: 1000 → 300; seed: 0 → 1)")
    assert normals.runs.stale_run(tmp_path, made) == "no record of the settings it was made with"
    lines = normals.storage_means(["png16", "floor8", "png16"], {"rpca": [1.0, 5.0, 2.0], "unps": [3.0, 4.0, 1.0]})
    assert [line.split() for line in lines] == [
        ["mean,", "png16", "(2)", "1.50°", "2.00°"], ["mean,", "floor8", "(1)", "5.00°", "4.00°"]]
    normals.runs.claim(tmp_path, ["preset.prior_weight=0"])
    normals.runs.claim(tmp_path, ["preset.prior_weight=0"])
    with pytest.raises(ValueError, match=r'made with \["preset.prior_weight=0"\], not \[\]: give another --tag'):
        normals.runs.claim(tmp_path, [])
    with pytest.raises(ValueError, match=r'not \[\]: delete the folder to run the study again$'):
        normals.runs.claim(tmp_path, [], way_out="delete the folder to run the study again")
    with pytest.raises(ValueError, match=r'not \["light=selfcal", "preset.prior_weight=0", '
                                         r'"light-network weights [0-9a-f]{12}"\]'):
        normals.runs.claim(tmp_path, normals.made_with("selfcal", ["preset.prior_weight=0"]))
    assert normals.run_folder(tmp_path, "default", "96") == tmp_path / "normals" / "default"
    assert normals.run_folder(tmp_path, "default", "12") == tmp_path / "normals" / "default-12"


def test_light_benchmark_rows_record_their_resolved_light_settings_and_stale_rows_say_why():
    """A row kept by the light benchmark can stand for a rerun only where every light setting,
    the defaults resolved, is the same: a default that changed since makes the row again."""
    benchmark = load_script("lb_benchmark", "experiments/light_benchmark/benchmark.py")
    made = benchmark.light_settings(None, ["selfcal.steps=500"])
    assert made["selfcal"]["steps"] == 500 and made["stages"] == ["reversal", "selfcal"]
    assert made["selfcal"]["device"] == "auto"          # ${device} resolved
    assert benchmark.stale({"stages": [], "light": made}, made) is None
    assert benchmark.stale({"stages": []}, made) == "made before rows recorded their light settings"
    now = benchmark.light_settings(None, [])
    assert benchmark.stale({"light": made}, now) == "made with other light settings (selfcal.steps: 500 → 1000)"


def test_light_benchmark_builds_and_runs_the_light_source_as_the_fit_does():
    """The light benchmark's source is ``light=selfcal``'s as ``python -m unps.fit`` builds it
    (``light.refine`` is the method's setting, not the estimator's), with its stages overridden."""
    benchmark = load_script("lb_benchmark", "experiments/light_benchmark/benchmark.py")
    source, names = benchmark.light_source(["reversal"], ["framings=[1.0]", "symmetric=false"])
    assert names == ["reversal"]
    subject = render_lambertian(shape="sphere", size=32, n_lights=8, seed=0)
    result = benchmark.run_case(source, subject)
    assert [s["stage"] for s in result["stages"]] == ["network", "reversal"]
    assert result["n_images"] == 8 and np.isfinite(result["stages"][-1]["dir"])
    with pytest.raises(InputError, match="not a light stage"):
        benchmark.light_source(["bogus"], [])[0](subject)
    slants = [f"{s['slant']:+.2f}°" for s in (result["stages"][0], result["stages"][-1])]
    assert benchmark.summary({("benchmark", "sphere", "8"): result}, names).splitlines()[-1].split()[-2:] == slants
    before = {**result, "stages": [{k: v for k, v in s.items() if k != "slant"} for s in result["stages"]]}
    assert benchmark.summary({("benchmark", "sphere", "8"): before}, names).splitlines()[-1].split()[-2:] == \
        ["—", "—"]


def test_adequacy_study_reads_each_fits_image_loss_and_keeps_the_free_fit_only_below_the_threshold():
    """From two benchmark runs of one sphere (the self-calibration held and free), the study's
    residual is the held fit's image loss (objective less the prior's pull) over the images'
    mean level, its gain the held error less the free one; the rule keeps the free fit only where
    the residual is under the threshold, and the report prints the case and its light count."""
    benchmark = load_script("lb_benchmark", "experiments/light_benchmark/benchmark.py")
    study = load_script("lb_adequacy", "experiments/light_benchmark/adequacy.py")
    subject = render_lambertian(shape="sphere", size=32, n_lights=12, seed=2)
    fast = ["framings=[1.0]", "symmetric=false", "selfcal.steps=200", "selfcal.frame_held_first=false"]
    held, free = (benchmark.run_case(benchmark.light_source(["selfcal"], fast + extra)[0], subject)
                  for extra in ([], ["selfcal.prior_weight=0", "selfcal.max_flattening_deg=null"]))
    level = study.level_of(subject)
    values = subject.observed_images()[:, subject.mask]
    assert level == pytest.approx(values.mean() / np.quantile(values, 0.99))
    row = study.features(held, free, level)
    evidence = held["stages"][-1]["evidence"]
    assert row["residual"] == pytest.approx((evidence["loss"] - evidence["prior"]) / level)
    assert row["gain"] == pytest.approx(held["stages"][-1]["dir"] - free["stages"][-1]["dir"])
    assert row["moved"] == free["stages"][-1]["evidence"]["moved_deg"] > 0
    assert study.kept([row], row["residual"] * 2) == (pytest.approx(row["free"]), pytest.approx(-row["gain"]))
    assert study.kept([row], row["residual"] / 2) == (pytest.approx(row["held"]), 0.0)
    declined = {"stages": [*held["stages"][:-1], {**held["stages"][-1], "evidence": {}}]}
    assert study.features(declined, free, level) is None
    text = study.report({("benchmark", "sphere", "12"): row, ("benchmark", "cube", "12"): {**row, "residual": 1.0},
                         ("benchmark", "cone", "12"): {**row, "gain": -1.5, "residual": 2.0}})
    lines = text.splitlines()
    assert any(line.split()[:3] == ["benchmark", "sphere", "12"] for line in lines) and "3 cases" in text
    assert lines[-1].split()[:2] == ["12", "3"]


def test_steepened_study_reads_the_network_lights_slant_and_the_error_of_steepening_them():
    """Lights read 2° nearer the view axis than the truth: slant bias −2°, and among the steps
    the error is lowest at +2° (where it is 0)."""
    steepened = load_script("lb_steepened", "experiments/light_benchmark/steepened.py")
    subject = render_lambertian(shape="sphere", size=24, n_lights=8, seed=0)
    flattened = steepened.steepened(subject.light_directions, -2.0)
    result = steepened.run_case(subject, lambda s: Lights(flattened, None, "estimated"))
    assert result["slant"] == pytest.approx(-2, abs=1e-3)
    assert result["errors"][steepened.STEPS.index(2.0)] == pytest.approx(0, abs=1e-3)
    assert result["errors"][0] == pytest.approx(2, abs=1e-3)
    last = steepened.report({("diligent", "ball", "8"): result}).splitlines()[-1].split()
    assert last[:5] == ["diligent", "8", "1", "-2.00°", "-2.00°"] and last[5 + steepened.STEPS.index(2.0)] == "0.00*"


def test_intensity_spread_scales_each_image_by_one_draw_and_reads_every_spread():
    """Each image is scaled by one factor within the spread (none for ``equal``); every spread is
    read, each from images scaled as it says."""
    study = load_script("lb_intensity_spread", "experiments/light_benchmark/intensity_spread.py")
    subject = render_lambertian(shape="sphere", size=24, n_lights=8, seed=0)
    rng = np.random.default_rng(0)
    assert study.rescaled(subject.images, None, rng) is subject.images
    scaled = study.rescaled(subject.images, (0.2, 2.0), rng)
    lit = subject.images > 0
    factors = scaled[lit] / subject.images[lit]
    per_image = [np.unique(np.round(scaled[i][lit[i]] / subject.images[i][lit[i]], 5)) for i in range(8)]
    assert all(len(f) == 1 and 0.2 <= f[0] <= 2.0 for f in per_image) and factors.std() > 0.1
    seen = []

    def network(s):
        seen.append(float(s.images.sum()))
        return Lights(subject.light_directions, None, "estimated")
    figures = study.read_spreads(subject, network, draws=2)
    assert list(figures) == list(study.SPREADS) and len(seen) == 1 + 2 * 2
    assert all(slant == pytest.approx(0, abs=1e-6) and error == pytest.approx(0, abs=1e-3)
               for slant, error in figures.values())
    assert seen[0] == pytest.approx(float(subject.images.sum())) and len(set(np.round(seen, 3))) == 5


def test_intensity_spread_refuses_weights_that_are_not_there(tmp_path, capsys, monkeypatch):
    study = load_script("lb_intensity_spread", "experiments/light_benchmark/intensity_spread.py")
    missing = tmp_path / "nope.pt"
    monkeypatch.setattr(sys, "argv", ["intensity_spread.py", "--set", f"checkpoint={missing}"])
    with pytest.raises(SystemExit) as stop:
        study.main()
    assert stop.value.code == 2
    assert f"{missing}: light-network weights not found" in capsys.readouterr().err


def test_slant_script_remeasures_runs_and_their_seed_ensemble(tmp_path, capsys, monkeypatch):
    """Two seeds of a fit, one 2° steeper and one 2° flatter than the truth: each reads ±2°, and
    their ensemble is the truth."""
    from omegaconf import OmegaConf
    slant = load_script("nir_slant", "experiments/neural_inverse_rendering/slant.py")
    cfg = hydra_config("subject=lambertian", "subject.size=24", "subject.n_lights=8")
    subject = render_lambertian(shape="sphere", size=24, n_lights=8, seed=cfg.seed)
    n = subject.normals[subject.mask].astype(np.float64)
    sin_slant = np.linalg.norm(n[:, :2], axis=1, keepdims=True)
    tilt = n[:, :2] / np.maximum(sin_slant, 1e-12)
    steeper = np.concatenate([n[:, 2:] * tilt, -sin_slant], 1)
    for folder, delta in [("Sphere-unps-fast", 2.0), ("Sphere-unps-fast-seed1", -2.0)]:
        (tmp_path / folder / ".hydra").mkdir(parents=True)
        OmegaConf.save(cfg, tmp_path / folder / ".hydra" / "config.yaml")
        normals = np.zeros_like(subject.normals)
        normals[subject.mask] = np.cos(np.radians(delta)) * n + np.sin(np.radians(delta)) * steeper
        np.save(tmp_path / folder / "normals.npy", normals)
    (tmp_path / "unfinished").mkdir()               # no normals.npy: skipped
    slant.main([str(p) for p in sorted(tmp_path.iterdir())] + ["--group-seeds"])
    lines = capsys.readouterr().out.splitlines()
    runs = [(line.split()[0], *map(float, line.split()[1:3])) for line in lines[1:3]]
    assert runs == [("Sphere-unps-fast", pytest.approx(2.0, abs=0.01), pytest.approx(2.0, abs=1e-6)),
                    ("Sphere-unps-fast-seed1", pytest.approx(2.0, abs=0.01), pytest.approx(-2.0, abs=1e-6))]
    row = lines[-1].split()
    assert row[0] == "Sphere-unps-fast" and row[4] == "2"
    assert float(row[2]) == pytest.approx(0, abs=1e-6) and float(row[5]) == pytest.approx(0, abs=1e-4)
    (tmp_path / "no-config").mkdir()
    np.save(tmp_path / "no-config" / "normals.npy", subject.normals)
    with pytest.raises(FileNotFoundError, match="config.yaml"):
        slant.main([str(tmp_path / "no-config")])
    np.save(tmp_path / "Sphere-unps-fast" / "normals.npy", subject.normals[:-1])
    with pytest.raises(ValueError, match=r"normals.npy: shape \(23, 24, 3\), expected the subject's \(24, 24, 3\)"):
        slant.main([str(tmp_path / "Sphere-unps-fast")])
    monkeypatch.setattr(slant, "instantiate", lambda *args, **kwargs: lambda: subject.replace(normals=None))
    with pytest.raises(ValueError, match="has no ground-truth normals"):
        slant.truth(tmp_path / "Sphere-unps-fast", {})


def test_concave_failures_tells_a_half_turn_from_a_distortion():
    from unps.lights.contour import best_rotation

    failures = load_script("concave_failures", "experiments/light_estimation/concave_failures.py")
    truth = np.random.default_rng(0).normal(size=(40, 3)) * [0.4, 0.4, 1.0]
    truth = truth * np.sign(truth[:, 2:]) / np.linalg.norm(truth, axis=1, keepdims=True)
    half_turn = truth * [-1, -1, 1]
    rotation = best_rotation(truth, half_turn)
    np.testing.assert_allclose(rotation, np.diag([-1.0, -1, 1]), atol=1e-9)
    assert failures.mapped_error(rotation, truth, half_turn) < 1e-4
    relief = np.array([[1.0, 0, 0.3], [0, 1, -0.2], [0, 0, 0.6]])     # a bas-relief-like map
    distorted = truth @ relief.T
    distorted /= np.linalg.norm(distorted, axis=1, keepdims=True)
    assert failures.mapped_error(best_rotation(truth, distorted), truth, distorted) > 3
    assert failures.mapped_error(failures.best_linear(truth, distorted), truth, distorted) < 2


def test_sheet_jars_scores_the_shipped_network_on_a_walled_jar_of_the_vases_outline():
    sheets = load_script("sheet_jars", "experiments/light_estimation/sheet_jars.py")
    from unps.lightnet.system import load_lightnet

    net, config = load_lightnet(None)
    walled, sheet = sheets.vase_jar(0.03, 40, 64), sheets.vase_jar(0.0, 40, 64)
    assert sheet.mask.sum() < walled.mask.sum()          # no lip ring around the mouth
    assert (sheet.normals[sheet.mask][:, 2] > 0).all()   # the inside seen from the side facing it
    error = sheets.symmetric_error(net, walled, stacks=2, resolution=config["recipe"]["resolution"])
    assert 0 < error < 20                                 # 7° over 48 stacks (its README)



def test_highlight_study_applies_each_variant_and_restores_the_shipped_thresholds():
    from test_highlights import VIEW, cap, glossy, unit

    from unps.inverse import highlights

    study = load_script("lb_highlights", "experiments/light_benchmark/highlights.py")
    shipped = tuple(getattr(highlights, name) for name in study.THRESHOLDS)
    assert study.VARIANTS["shipped"] == shipped
    lights = cap(96)
    truth = unit(lights[:40] + VIEW + 0.01)
    fit = unit(truth + [0.5, 0, 0])                                   # 25° off: what the fit left
    error, share = study.with_rule(fit, truth, glossy(truth, lights), lights, shipped)
    assert share == 1 and error < 3
    error, share = study.with_rule(fit, truth, glossy(truth, lights), lights, (5.0, 0.4, 6, 5.0))
    assert share == 0 and error > 20                                  # the lights too sparse for 5°
    assert tuple(getattr(highlights, name) for name in study.THRESHOLDS) == shipped


def test_free_fit_study_finds_a_shared_transform_its_bas_relief_and_the_elevation_stretch():
    study = load_script("lb_free_fits", "experiments/light_benchmark/free_fits.py")
    rng = np.random.default_rng(0)
    polar, azimuth = np.radians(rng.uniform(5, 40, 30)), rng.uniform(0, 2 * np.pi, 30)
    start = np.stack([np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth), np.cos(polar)], 1)
    bas_relief = np.array([[1, 0, 0], [0, 1, 0], [0.2, -0.1, 0.8]])      # all the lights moved together
    moved = start @ bas_relief
    moved /= np.linalg.norm(moved, axis=1, keepdims=True)
    def degrees(a, b):
        return np.degrees(np.arccos(np.clip((a * b).sum(1), -1, 1))).mean()

    assert degrees(study.frame_only(start, moved), moved) < 0.5
    alone = moved + rng.normal(0, 0.05, moved.shape)                       # and each on its own
    alone /= np.linalg.norm(alone, axis=1, keepdims=True)
    assert degrees(study.frame_only(start, alone), alone) > 2
    wider = np.stack([np.sin(1.2 * polar) * np.cos(azimuth), np.sin(1.2 * polar) * np.sin(azimuth),
                      np.cos(1.2 * polar)], 1)
    assert study.elevation_stretch(start, wider) == pytest.approx(1.2)
    assert study.elevation_stretch(start, start) == pytest.approx(1.0)
    lights_bas_relief = start @ np.array([[1, 0, 0.2], [0, 1, -0.1], [0, 0, 0.8]])   # z' = μx + νy + λz
    lights_bas_relief /= np.linalg.norm(lights_bas_relief, axis=1, keepdims=True)
    assert degrees(study.bas_relief_only(start, lights_bas_relief), lights_bas_relief) < 0.01
    turn = np.radians(10.0)                                                  # about the x axis: no bas-relief
    turned = start @ np.array([[1, 0, 0], [0, np.cos(turn), np.sin(turn)], [0, -np.sin(turn), np.cos(turn)]])
    assert degrees(study.bas_relief_only(start, turned), turned) > 2
    assert degrees(study.frame_only(start, turned), turned) < 0.5


def test_error_by_angle_splits_the_mean_into_bands_that_add_up():
    study = load_script("calibrated_error_by_angle", "experiments/calibrated/error_by_angle.py")
    from_view = np.radians([10.0, 40.0, 60.0, 70.0, 80.0])
    truth = np.stack([np.sin(from_view), np.zeros(5), np.cos(from_view)], 1)
    error = np.array([1.0, 2.0, 3.0, 4.0, 40.0])
    rows = study.bands(error, truth)
    assert [share for _, share, _, _ in rows[:5]] == [0.2] * 5
    assert sum(adds for _, _, _, adds in rows[:5]) == pytest.approx(error.mean())
    assert rows[5][1:] == (0.2, 40.0, 8.0)


def test_reflectance_spread_reads_each_run_and_names_one_without_reflectance(tmp_path, capsys):
    """One albedo for every image spreads 0; a pixel lit twice as bright in half its images
    spreads 1/3 (std 0.5 over mean 1.5); a folder without reflectance.npy is named, exit 2."""
    study = load_script("calibrated_reflectance_spread", "experiments/calibrated/reflectance_spread.py")
    reflectance = np.ones((4, 1, 3, 3))
    reflectance[:2, 0, 1] = 2.0
    reflectance[:, 0, 2] = 0.0                                      # off the object
    run = tmp_path / "run"
    run.mkdir()
    np.save(run / "reflectance.npy", reflectance)
    (run / "metrics.json").write_text('{"normal_mae": 1.5, "slant_bias": 0.25}')
    assert study.reflectance_spread(reflectance).tolist() == pytest.approx([0.0, 1 / 3])
    assert study.main([str(run)]) == 0
    assert "0.167" in capsys.readouterr().out.splitlines()[1]      # the mean of 0 and 1/3
    assert study.main([str(tmp_path / "missing")]) == 2
    assert "missing: no reflectance.npy" in capsys.readouterr().err


def test_last_steps_averages_the_normals_of_each_window_of_the_last_steps(capsys):
    """N_o that swings ±10° about the truth from step to step is 10° off at every step, and its
    unit mean over an even number of the last steps is on the truth; steps before the longest
    window are not read."""
    study = load_script("calibrated_last_steps", "experiments/calibrated/last_steps.py")
    import torch

    tilt = np.radians(10.0)
    truth = torch.tensor([0.0, 0.0, 1.0]).view(1, 3, 1, 1).expand(1, 3, 4, 4)

    class Module:
        true_normals, step = truth, 0

        def normals(self):
            side = 1.0 if self.step % 2 else -1.0
            n = torch.tensor([side * np.sin(tilt), 0.0, np.cos(tilt)], dtype=torch.float32)
            return n.view(1, 3, 1, 1).expand(1, 3, 4, 4), None

        def normal_mae(self, normals):
            cos = (normals * self.true_normals).sum(1).clamp(-1, 1)
            return torch.rad2deg(torch.acos(cos)).mean()

    class Trainer:
        max_steps, global_step = 400, 0

    callback, trainer, module = study.LastSteps(), Trainer(), Module()
    for step in range(1, 401):
        trainer.global_step = module.step = step
        callback.on_train_batch_end(trainer, module, None, None, 0)
    callback.on_train_end(trainer, module)
    assert len(callback.errors) == 300
    printed = capsys.readouterr().out.splitlines()
    assert printed[0].endswith("mean 10.00°, lowest 10.00°, highest 10.00°, last 10.00°")
    assert [line.split(": ")[1] for line in printed[1:]] == ["0.40°", "0.00°", "0.00°", "0.00°", "0.00°"]


def test_light_moves_splits_a_move_of_the_lights_into_a_common_turn_and_the_rest(capsys):
    study = load_script("lb_light_moves", "experiments/light_benchmark/light_moves.py")
    truth = render_lambertian("sphere", size=8, n_lights=12, seed=1).light_directions
    angle = np.radians(5)
    about_x = np.array([[1, 0, 0], [0, np.cos(angle), -np.sin(angle)], [0, np.sin(angle), np.cos(angle)]])
    turned = truth @ about_x.T
    back = study.decompose(turned, truth, truth)         # a turn undone: all of it a turn
    assert back["turn"] == pytest.approx(5, abs=1e-3) and back["turn_only"] < 1e-3
    assert back["rest_only"] == pytest.approx(back["before"], abs=1e-3)
    flatter = truth * [1, 1, 0.8]
    flatter /= np.linalg.norm(flatter, axis=1, keepdims=True)
    lowered = study.decompose(truth, flatter, truth)     # elevations lowered: no turn
    assert lowered["turn"] < 0.2 * lowered["moved"]                          # measured 0.79° of 5.95°
    assert lowered["rest_only"] == pytest.approx(lowered["after"], abs=0.1 * lowered["after"])
    text = study.summary([back, lowered])
    assert text.splitlines()[0].startswith("mean (2)")
    # back's turn undoes its error; lowered starts from the truth, so its small turn and its rest raise it
    assert ("the turn alone lowers the error on 1, raises it on 1; the rest alone lowers it on 0, "
            "raises it on 1") in text
    with pytest.raises(SystemExit):
        study.main([])                                   # neither two folders nor --selfcal
    assert "give BEFORE and AFTER run folders, or --selfcal" in capsys.readouterr().err


def test_light_moves_splits_off_a_common_linear_map_of_the_scaled_lights(tmp_path, capsys):
    study = load_script("lb_light_moves", "experiments/light_benchmark/light_moves.py")
    truth = render_lambertian("sphere", size=8, n_lights=12, seed=1).light_directions.astype(np.float64)
    bas_relief = np.array([[1, 0, 0], [0, 1, 0], [0.2, -0.1, 0.8]])           # a GBR of the lights
    skewed = truth @ bas_relief
    back = study.decompose_linear(skewed, truth, truth)                      # undone: all of it linear
    assert back["linear_only"] < 1e-6 and back["rest_only"] == pytest.approx(back["before"], abs=1e-6)
    assert back["linear"] == pytest.approx(back["moved"], abs=1e-6) and back["before"] > 5
    nudged = truth + 0.05 * np.random.default_rng(0).normal(size=truth.shape)   # each light on its own
    nudged /= np.linalg.norm(nudged, axis=1, keepdims=True)
    one = study.decompose_linear(truth, nudged, truth)
    assert one["linear"] < 0.5 * one["moved"] and one["rest_only"] > 2 * one["linear_only"]
    text = study.summary([back, one])
    assert "the linear alone lowers the error on 1" in text
    assert "the whole move raises it by more than 1° on 1, by more than 2° on 1" in text

    def write(folder: Path, directions: np.ndarray, intensities: np.ndarray) -> None:
        folder.mkdir(parents=True)
        np.savetxt(folder / "lights.txt", np.hstack([directions, np.repeat(intensities[:, None], 3, 1)]))
        np.savetxt(folder / "lights_gt.txt", truth)

    scales = np.linspace(0.5, 2, len(truth))
    write(tmp_path / "before" / "ball-woodham", skewed / np.linalg.norm(skewed, axis=1, keepdims=True),
          np.linalg.norm(skewed, axis=1) * scales)
    write(tmp_path / "after" / "ball-unps", truth, scales)
    np.testing.assert_allclose(study.read_scaled_lights(tmp_path / "after" / "ball-unps" / "lights.txt"),
                               truth * (scales / np.exp(np.log(scales).mean()))[:, None])
    study.main([str(tmp_path / "before"), str(tmp_path / "after"), "--linear"])
    printed = capsys.readouterr().out.splitlines()
    assert printed[0].split() == ["object", "before", "after", "moved", "linear", "linear", "only", "rest",
                                  "only"]
    assert printed[1].startswith("ball") and printed[1].split()[5] == "0.00°"   # the linear map alone: exact


def test_selfcal_steps_reads_the_final_lights_off_both_fits_as_the_default_decides(capsys):
    """The held fit where it flattens the lights no more than the limit at the stop; the pulled fit
    where it does; the start where both do; and so under a looser limit read off the same traces."""
    study = load_script("lb_selfcal_steps", "experiments/light_benchmark/selfcal_steps.py")
    held_kept = {"network": 10.0, "start": 8.0, "max_flattening_deg": 1.0, "inside_out": False, "pulled": None,
                 "held": {"trace": [[0, 8.0, 0.0], [100, 7.0, 0.2], [200, 6.0, 0.5], [250, 6.0, 0.6]]}}
    pulled_late = {"network": 6.0, "start": 5.0, "max_flattening_deg": 1.0, "inside_out": False,  # flattens at 200
                   "held": {"trace": [[0, 5.0, 0.0], [100, 4.5, 0.5], [200, 7.5, 1.5], [250, 7.0, 1.8]]},
                   "pulled": {"trace": [[0, 5.0, 0.0], [100, 5.5, 0.1], [200, 5.8, 0.2], [250, 6.5, 1.2]]}}
    assert study.final(held_kept, lambda fit: 200) == (6.0, 200)
    assert study.final(pulled_late, lambda fit: 100) == (4.5, 100)          # held kept at 100
    assert study.final(pulled_late, lambda fit: 200) == (5.8, 400)          # held declined, pulled kept
    assert study.final(pulled_late, lambda fit: 250) == (5.0, 500)          # both declined: the start
    assert study.final({**pulled_late, "inside_out": True, "held": None, "pulled": None},
                       lambda fit: 200) == (5.0, 0)                          # no fit at all
    reads = [[[0.0, 0.0, 1.0]], [[0.1, 0.0, 0.995]], [[0.2, 0.0, 0.98]], [[0.3, 0.0, 0.954]]]
    traced = {**pulled_late, "held": {**pulled_late["held"], "directions": reads},
              "pulled": {**pulled_late["pulled"], "directions": reads[::-1]}}
    assert study.final_directions(traced, lambda fit: 100).tolist() == reads[1]    # the held fit's
    assert study.final_directions(traced, lambda fit: 200).tolist() == reads[1]    # the pulled fit's 200
    assert study.final_directions(traced, lambda fit: 250).tolist() == reads[0]    # the start's
    assert study.final_directions({**traced, "inside_out": True, "held": None, "pulled": None},
                                  lambda fit: 200) is None                   # no trace of the start
    names, cases = ["held_kept", "pulled_late"], [held_kept, pulled_late]
    line = study.summary_line("step 200", cases, names, lambda fit: 200)
    assert line.split()[:7] == ["step", "200", "5.90°", "ratio", "0.738", "steps", "300"]
    assert "raised >1°:  0" in line and "worst +0.80° (pulled_late)" in line
    assert "vs the full length: 1 above, 0 below" in line                    # 5.8° against the start's 5.0°
    looser = [study.with_limit(case, 2.0) for case in cases]                # held flattened 1.5° at 200: kept
    assert study.final(looser[1], lambda fit: 200) == (7.5, 200)
    assert study.final(study.with_limit(pulled_late, None), lambda fit: 250) == (7.0, 250)
    assert study.changed_cases(cases, looser, names, lambda fit: 200) == "pulled_late 5.80° → 7.50°"
    assert study.changed_cases(cases, cases, names, lambda fit: 200) == "none"
    with pytest.raises(ValueError, match="a limit of 0.5° cannot be read off traces made with max_flattening_deg=1.0"):
        study.with_limit(pulled_late, 0.5)
    assert study.limit_value("none") is None and study.limit_value("1.5") == 1.5
    with pytest.raises(SystemExit):
        study.main(["--report", "--limits", "loose"])
    assert "--limits: 'loose': give degrees (e.g. 1.5) or none" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        study.main(["--steps", "300", "--marks", "250", "400"])
    assert "--marks [250, 400]: each must be a multiple of 100 up to --steps (300)" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        study.main(["--set", "selfcal.lr_lights=0.006"])
    assert "--set: give the run its own --tag (or --out)" in capsys.readouterr().err


def test_selfcal_steps_names_a_setting_the_config_lacks_and_makes_no_folder(capsys, tmp_path):
    study = load_script("lb_selfcal_steps", "experiments/light_benchmark/selfcal_steps.py")
    with pytest.raises(SystemExit):
        study.main(["--set", "selfcal.no_such_setting=1", "--tag", "x", "--cache", str(tmp_path)])
    assert "selfcal.no_such_setting" in capsys.readouterr().err
    assert not (tmp_path / "results").exists()


def test_selfcal_steps_reads_the_marks_and_settle_lines_under_the_limit_asked_for(capsys, tmp_path):
    """``--limit`` applies to every case before the lines are read; a limit below the one the
    traces are made with is refused before any folder is made."""
    study = load_script("lb_selfcal_steps", "experiments/light_benchmark/selfcal_steps.py")
    flattens = {"network": 6.0, "start": 5.0, "max_flattening_deg": 1.0, "inside_out": False,
                "held": {"trace": [[0, 5.0, 0.0], [100, 4.0, 1.2]]},
                "pulled": {"trace": [[0, 5.0, 0.0], [100, 4.5, 0.1]]}}
    assert study.final(study.with_limit(flattens, study.TRACED), lambda fit: 100) == (4.5, 200)
    assert study.final(study.with_limit(flattens, study.limit_value("1.5")), lambda fit: 100) == (4.0, 100)
    with pytest.raises(SystemExit):
        study.main(["--limit", "0.5", "--set", "selfcal.max_flattening_deg=1", "--tag", "x",
                    "--cache", str(tmp_path)])
    assert "--limit: a limit of 0.5° cannot be read off traces made with max_flattening_deg=1" in \
        capsys.readouterr().err
    assert not (tmp_path / "results").exists()
    with pytest.raises(SystemExit):
        study.main(["--report", "--limits", "traced"])
    assert "--limits: give degrees or none" in capsys.readouterr().err


def test_rounds_trace_reads_each_rounds_lights_off_the_fits_starts():
    """Round k + 1's fit starts from round k's lights; a round made but not kept adds one fit that
    starts from the lights returned; fits before the rounds (both readings, a declined held fit)
    are skipped; a case whose rounds stopped early keeps its last lights in the later columns."""
    study = load_script("lb_rounds_trace", "experiments/light_benchmark/rounds_trace.py")

    def light(x):
        return np.array([[x, 0.0, 1.0]])

    reads = [(0, light(0)), (100, light(0.5)), (200, light(0.6)),       # the reading as read
             (0, light(5)), (200, light(5.5)),                             # its half turn
             (0, light(0)), (300, light(1)),                               # round 1 (first fit)
             (0, light(1)), (300, light(2)),                               # round 2
             (0, light(2)), (300, light(7))]                               # round 3: not kept
    starts = study.fit_starts(reads)
    assert [float(s[0, 0]) for s in starts] == [0, 5, 0, 1, 2]
    assert [float(k[0, 0]) for k in study.kept_after_rounds(starts, light(2), made=2)] == [1, 2]
    assert [float(k[0, 0]) for k in study.kept_after_rounds(starts[:4], light(2), made=2)] == [1, 2]
    assert [float(k[0, 0]) for k in study.kept_after_rounds(starts[:3], light(1), made=1)] == [1]
    case = {"network": 4.0, "rounds": [3.0, 2.0]}
    assert [study.after_round(case, k) for k in (1, 2, 3)] == [3.0, 2.0, 2.0]
    line = study.case_line("benchmark", "blob01", "12", case, 3)
    assert line.split()[-3:] == ["3.00°", "2.00°", "·"]
    other = {"network": 2.0, "rounds": [1.0, 1.0, 1.0, 2.0]}
    lines = study.set_lines([case, other], ["blob01", "blob02"], 4)
    assert lines[1].split()[1:] == ["2.00°", "1.50°", "1.50°", "2.00°"]
    assert lines[2].split()[1:] == ["0.67", "0.50", "0.50", "0.67"]
    assert lines[3].endswith("above round 3's by > 0.3°: blob02 1.00° → 2.00°")
    assert lines[4].endswith("below round 3's by > 0.3°: none")


def test_rounds_trace_refuses_no_rounds_before_it_makes_anything(capsys, tmp_path):
    study = load_script("lb_rounds_trace", "experiments/light_benchmark/rounds_trace.py")
    with pytest.raises(SystemExit):
        study.main(["--rounds", "0", "--cache", str(tmp_path)])
    assert "--rounds must be at least 1, got 0" in capsys.readouterr().err
    assert not (tmp_path / "results").exists()


def test_selfcal_steps_stops_each_trace_where_its_lights_settle():
    study = load_script("lb_selfcal_steps", "experiments/light_benchmark/selfcal_steps.py")

    def turned(degrees):                       # two lights, both turned about y by ``degrees``
        t = np.radians(degrees)
        return [[np.sin(t), 0.0, np.cos(t)], [np.sin(t + 0.5), 0.0, np.cos(t + 0.5)]]

    settling = {"trace": [[0, 5.0, 0], [100, 4.0, 0], [200, 3.5, 0], [300, 3.4, 0]],
                "directions": [turned(0), turned(5), turned(5.5), turned(5.51)]}
    moving = {"trace": [[0, 5.0, 0], [100, 4.0, 0], [200, 6.5, 0], [300, 7.0, 0]],
              "directions": [turned(0), turned(5), turned(10), turned(10.01)]}
    assert study.settled_step(settling, 1.0) == 200        # 0.5° from step 100 to 200
    assert study.settled_step(settling, 0.1) == 300        # the last read: the fit ends there anyway
    assert study.settled_step(settling, 0) == 300          # 0: every step
    assert study.settled_step(moving, 1.0) == 300
    cases = [{"network": 6.0, "start": 5.0, "max_flattening_deg": 1.0, "inside_out": False, "held": fit,
              "pulled": None}
             for fit in (settling, moving)]
    line = study.summary_line("settle 1°", cases, ["settling", "moving"], lambda fit: study.settled_step(fit, 1.0))
    assert line.split()[:7] == ["settle", "1°", "5.25°", "ratio", "0.875", "steps", "250"]
    assert "raised >1°:  1" in line and "worst +2.00° (moving)" in line and "0 above, 0 below" in line


def test_outline_ring_splits_the_error_by_distance_to_the_outline(tmp_path, capsys):
    """DiLiGenT's ball with its true normals and its outermost ring turned to face the camera: the
    ring holds all of the error, the bands further in none; a missing fit is named."""
    study = load_script("calibrated_outline_ring", "experiments/calibrated/outline_ring.py")
    diligent = diligent_object("pmsData/ballPNG").parents[1]
    ball = study.truth("ball", diligent, tmp_path, tmp_path)
    ring = ball.mask & (outline_distance(ball.mask) <= 1)
    normals = np.where(ring[..., None], [0.0, 0.0, 1.0], ball.normals)
    (tmp_path / "ball-unps").mkdir()
    np.save(tmp_path / "ball-unps" / "normals.npy", normals)
    study.main(["--runs", str(tmp_path), "--objects", "ball", "--diligent", str(diligent)])
    line = capsys.readouterr().out.splitlines()[-1]
    assert "(0,1]" in line and "100.0%" in line and " 0.0° " in line.split("|")[2]
    with pytest.raises(SystemExit, match="cat-unps/normals.npy: not found"):
        study.main(["--runs", str(tmp_path), "--objects", "cat", "--diligent", str(diligent)])


def test_grid_floor_names_a_missing_diligent_folder(tmp_path, capsys):
    """--diligent points the grid-floor study at DiLiGenT; a folder that is not there is named."""
    grid_floor = load_script("grid_floor", "experiments/calibrated/grid_floor.py")
    missing = tmp_path / "no-diligent"
    with pytest.raises(SystemExit, match=f"{missing}: DiLiGenT not found \\(give --diligent"):
        grid_floor.main(["--diligent", str(missing)])
    assert capsys.readouterr().out == ""


def test_light_benchmark_normals_tells_each_light_stages_mean_error_ratio_and_raises():
    """The uncalibrated rows end with the lights after each stage: the mean direction error, its
    ratio to the network's, and the objects a stage left more than 1° / 2° worse."""
    normals = load_script("lb_normals", "experiments/light_benchmark/normals.py")

    def run(*errors):
        return [{"stage": s, "light_dir_mae": e} for s, e in zip(("network", "selfcal", "fit"), errors)]

    lines = normals.stage_lines(["a", "b", "c"], [run(6.0, 4.0, 3.0), run(3.0, 5.5, 5.0), run(9.0, 10.5, 7.0)])
    assert [line.split()[:5] for line in lines[1:]] == [
        ["network", "6.00°", "1.00", "0", "0"], ["selfcal", "6.67°", "1.11", "2", "1"],
        ["fit", "5.00°", "0.83", "0", "0"]]
    assert lines[2].endswith("+2.50° (b)")
    assert "worst" not in lines[3] and "(" not in lines[3]
    with pytest.raises(ValueError, match="different light stages"):
        normals.stage_lines(["a", "b"], [run(1.0, 2.0, 3.0), run(1.0, 2.0)])


def test_light_benchmark_runs_are_held_by_one_process_at_a_time(tmp_path):
    """A row being fitted by a live process is not started again beside it (its run folder holds
    the process id); a mark left by a process that has ended is taken over, and removed after."""
    runs = load_script("lb_runs", "experiments/light_benchmark/runs.py")
    normals = load_script("lb_normals", "experiments/light_benchmark/normals.py")
    obj = normals.scenes.OBJECTS[0]
    busy = tmp_path / f"{obj.name}-rpca"
    busy.mkdir()
    (busy / runs.MARK).write_text(str(os.getppid()))          # a live process: the test's parent
    with pytest.raises(SystemExit, match=f"being run by process {os.getppid()}"):
        normals.run_row(tmp_path / "nowhere", obj, "rpca", "gt", [], tmp_path)
    ended = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                           capture_output=True, text=True, check=True)
    (busy / runs.MARK).write_text(ended.stdout.strip())       # a process that has ended
    with runs.held(busy):
        assert (busy / runs.MARK).read_text() == str(os.getpid())
    assert not (busy / runs.MARK).exists()


def test_light_stage_timing_table_gives_each_stages_median_and_the_last_rounds_lights():
    """experiments/speed/light_stages.py: the median over the rounds of each light stage's seconds,
    before → now, and the light error of the last round."""
    light_stages = load_script("light_stages", "experiments/speed/light_stages.py")

    def run(seconds: float, error: float) -> dict:
        return {"light network": 2.0, "reversal test": seconds / 10, "self-calibration": seconds,
                "lights": seconds + 5, "light_dir_mae": error}

    runs = {("cat", "before"): [run(30.0, 4.6), run(50.0, 4.6), run(31.0, 4.6074)],
            ("cat", "now"): [run(26.0, 4.6), run(24.0, 4.6), run(40.0, 4.6084)]}
    header, rule, row = light_stages.table(runs, ["cat"]).splitlines()
    assert header.startswith("| subject | light network (s), before → now |")
    assert rule == "|---" * 6 + "|"
    assert row == "| cat | 2.0 → 2.0 | 3.1 → 2.6 | 31.0 → 26.0 | 36.0 → 31.0 | 4.6074 → 4.6084 |"


def test_speed_comparison_table_shows_the_named_stages_before_and_now():
    """experiments/speed/compare.py: one row per subject, the stages asked for between the fit's
    seconds per step and the normal error."""
    compare = load_script("speed_compare", "experiments/speed/compare.py")

    def run(wall: float, read_out: float, mae: float) -> dict:
        return {"wall_s": wall, "fit_s": wall - 10, "s_per_step": 0.1, "normal_mae": mae,
                "stage_seconds": {"read-out": read_out, "steps": 90.0}}

    header, rule, row = compare.table({"pot1": (run(120.0, 8.04, 6.2213), run(115.5, 3.61, 6.2224))},
                                      ["read-out"]).splitlines()
    assert header == ("| subject | wall before → now (s) | fit before → now (s) | s/step before → now "
                      "| read-out before → now (s) | MAE before → now | Δ MAE (°) |")
    assert rule == "|---" * 7 + "|"
    assert row == "| pot1 | 120.0 → 115.5 | 110.0 → 105.5 | 0.100 → 0.100 | 8.04 → 3.61 | 6.221 → 6.222° | +0.001 |"


def test_light_stage_timing_refuses_no_rounds_before_it_makes_anything(tmp_path, capsys):
    """experiments/speed/light_stages.py --rounds 0 stops with the value named, before a worktree
    or a run folder is made."""
    light_stages = load_script("light_stages", "experiments/speed/light_stages.py")
    with pytest.raises(SystemExit):
        light_stages.main(["--before", "HEAD", "--rounds", "0", "--out", str(tmp_path / "runs")])
    assert "--rounds must be at least 1, got 0" in capsys.readouterr().err
    assert not (tmp_path / "runs").exists()


def test_integrability_study_finds_the_frame_of_a_lambertian_surface_up_to_its_bas_relief():
    """Images of a smooth Lambertian surface (no shadows) are rank 3; the integrability constraint on
    their low-rank normals gives the frame the true lights give, the lights it leads to are a
    bas-relief of the truth, and the nearest bas-relief reaches a reading inside out."""
    study = load_script("lb_integrability", "experiments/light_benchmark/integrability.py")
    rows, cols = np.mgrid[0:48, 0:48] / 47.0
    depth = 6 * np.exp(-((cols - 0.4) ** 2 + (rows - 0.5) ** 2) / 0.08) + 3 * np.sin(3 * cols) * rows
    slope_x, slope_y = np.gradient(depth, axis=1), -np.gradient(depth, axis=0)      # y up
    normals = study.unit(np.stack([-slope_x, -slope_y, np.ones_like(depth)], -1))
    albedo = 0.6 + 0.3 * cols
    rng = np.random.default_rng(1)
    polar, azimuth = np.radians(rng.uniform(5, 25, 20)), rng.uniform(0, 2 * np.pi, 20)
    truth = np.stack([np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth), np.cos(polar)], 1)
    mask = np.ones(depth.shape, bool)
    gray = (albedo[..., None] * normals)[mask] @ truth.T                               # (m, n)
    assert gray.min() > 0                                                               # no shadow
    scaled, images_lights = study.rank3(gray)
    true_frame = np.linalg.inv(np.linalg.lstsq(images_lights, truth, rcond=None)[0]).T
    grid = np.zeros(depth.shape + (3,))
    grid[mask] = scaled
    c = study.null_vector(study.constraint_rows(grid, mask))
    assert abs(c @ study.constraint_of(true_frame)) > 0.999
    assert abs(study.constraint_of(study.frame_from(c)) @ c) == pytest.approx(1.0)
    integrable = images_lights @ np.linalg.inv(study.frame_from(c)).T
    def degrees(a, b):
        return np.degrees(np.arccos(np.clip((study.unit(a) * b).sum(1), -1, 1))).mean()
    assert degrees(integrable, truth) > 5                                               # some bas-relief of it …
    assert degrees(study.nearest_bas_relief(integrable, truth), truth) < 0.5            # … and only that
    inside_out = truth * [-1, -1, 1]
    assert degrees(study.nearest_bas_relief(truth, inside_out), inside_out) < 0.01


def test_light_parts_measures_the_intensity_error_and_swaps_only_the_lights_files(tmp_path):
    """The intensity error ignores a common scale; a smooth brightening across the dome is all
    'linear', one light by light hardly any; a mixed capture reads as the original but for its lights."""
    study = load_script("lb_light_parts", "experiments/light_benchmark/light_parts.py")
    assert doctest.testmod(study).failed == 0   # the errors, the shares and the summary's means
    sphere = render_lambertian("sphere", size=32, n_lights=24, seed=3)
    directions, true = sphere.light_directions, sphere.light_intensities
    assert study.intensity_error(3 * true, true) == pytest.approx(0, abs=1e-6)
    assert study.intensity_error(true * np.tile([1.1, 0.9], 12)[:, None], true) == pytest.approx(0.1, rel=0.02)
    smooth = true * np.exp(directions @ np.array([0.2, -0.3, 0.5]))[:, None]
    assert study.linear_share(directions, smooth, true) == pytest.approx(1, abs=1e-6)
    jitter = true * np.exp(np.random.default_rng(0).normal(0, 0.1, (24, 1)))
    assert study.linear_share(directions, jitter, true) < 0.4
    write_diligent(sphere, tmp_path / "capture")
    other = directions[::-1].copy()
    mixed = study.mixed_capture(tmp_path / "capture", other, smooth, tmp_path / "mixed")
    original, swapped = read_diligent(tmp_path / "capture"), read_diligent(mixed)
    np.testing.assert_allclose(swapped.light_directions, other, atol=1e-6)
    assert study.intensity_error(swapped.light_intensities, smooth) == pytest.approx(0, abs=1e-6)
    np.testing.assert_allclose(swapped.images * swapped.light_intensities[:, None, None, :],
                               original.images * original.light_intensities[:, None, None, :], atol=1e-5)
    assert all((mixed / f.name).is_symlink() for f in (tmp_path / "capture").iterdir()
               if not f.name.startswith("light_"))


def test_operation_profile_names_each_convolution_shape_and_pass(capsys, tmp_path):
    """experiments/speed/ops.py: forward and backward convolutions by shape, per step, largest
    first, with their share of all the profiled time; other operations left out; --steps 1 refused."""
    from types import SimpleNamespace as Event
    ops = load_script("speed_ops", "experiments/speed/ops.py")
    assert doctest.testmod(ops).failed == 0
    events = [Event(key="aten::convolution_backward", self_cpu_time_total=3000.0,
                    input_shapes=[[1, 48, 9, 9], [1, 289, 9, 9], [48, 289, 1, 1], [], []]),
              Event(key="aten::mkldnn_convolution", self_cpu_time_total=1000.0,
                    input_shapes=[[1, 289, 9, 9], [48, 289, 1, 1], [48]]),
              Event(key="aten::leaky_relu", self_cpu_time_total=1000.0, input_shapes=[[1, 48, 9, 9]])]
    assert ops.convolution_rows(events, steps=100) == [
        ("in (1, 289, 9, 9) → 48, 1×1", "backward", 0.03, 0.6),
        ("in (1, 289, 9, 9) → 48, 1×1", "forward", 0.01, 0.2)]
    with pytest.raises(SystemExit):
        ops.main(["--steps", "1", "--out", str(tmp_path / "runs")])
    assert "--steps must be at least 2, got 1" in capsys.readouterr().err
    assert not (tmp_path / "runs").exists()


def test_light_benchmark_gallery_shows_the_frontal_image_and_reads_each_light_sets_errors(tmp_path):
    gallery = load_script("lb_gallery", "experiments/light_benchmark/gallery.py")
    mask = np.zeros((4, 4), bool)
    mask[1:3, 1:3] = True
    images = np.zeros((2, 4, 4, 3), np.float32)
    images[0, mask] = 2.0
    images[1, mask] = 1.0
    directions = np.array([[0.6, 0, 0.8], [0, 0, 1.0]], np.float32)
    picture = gallery.frontal_image(images, directions, mask)
    np.testing.assert_allclose(picture[mask], 0.5)      # the second image, at half the 99th percentile
    assert (picture[~mask] == 1).all()
    (tmp_path / "benchmark-blob01-20.json").write_text(json.dumps(
        {"stages": [{"stage": "network", "dir": 7.06}, {"stage": "selfcal", "dir": 6.81}]}))
    assert gallery.stage_errors(tmp_path, "blob01") == "96: –  20: 7.1→6.8°  12: –"


def test_light_benchmark_gallery_names_a_results_folder_that_is_not_there(tmp_path):
    """--tag that no benchmark run wrote: exit 2, the folder named, no picture written."""
    out = tmp_path / "objects.png"
    done = subprocess.run([sys.executable, "experiments/light_benchmark/gallery.py", "--cache", str(tmp_path),
                           "--tag", "nope", "--out", str(out)],
                          capture_output=True, text=True, cwd=Path(__file__).parents[1])
    assert done.returncode == 2
    assert f"--tag nope: no results folder {tmp_path / 'results' / 'nope'}" in done.stderr
    assert not out.exists()


def test_light_benchmark_single_material_group_is_the_same_objects_in_their_first_material(tmp_path, monkeypatch):
    """``--only single``: each of the 24 objects with the same shape, seed (pose, lights, camera)
    and storage, in the first of its materials alone; cached apart from the painted objects, and
    read as its own group."""
    benchmark = load_script("lb_benchmark", "experiments/light_benchmark/benchmark.py")
    scenes = benchmark.scenes
    assert len(scenes.SINGLE_MATERIAL) == len(scenes.OBJECTS) == 24
    for one, painted in zip(scenes.SINGLE_MATERIAL, scenes.OBJECTS):
        assert (one.name, one.shape, one.seed, one.storage) == (
            painted.name, painted.shape, painted.seed, painted.storage)
        assert one.materials == painted.materials[:1] and len(painted.materials) >= 2
        assert one.key() != painted.key()
    mask = np.zeros((32, 32), bool)
    mask[4:28, 6:30] = True
    assert set(np.unique(scenes.material_map(mask, 1, seed=3)[mask])) == {0}
    assert set(np.unique(scenes.material_map(mask, 2, seed=3)[mask])) == {0, 1}

    made = []
    monkeypatch.setattr(scenes, "make_captures", lambda obj, data, cache: made.append(obj) or {"12": tmp_path})
    monkeypatch.setattr(benchmark, "read_diligent", lambda folder, name, quantization: (name, quantization))
    found = list(benchmark.cases(["single"], ["12"], tmp_path, tmp_path, names=["blob01", "pits"]))
    assert [(group, name, label) for group, name, label, _ in found] == [
        ("single", "blob01", "12"), ("single", "pits", "12")]
    assert [read() for *_, read in found] == [("blob01", "floor"), ("pits", "round")]
    assert [obj.materials for obj in made] == [("white-diffuse-bball",), ("colonial-maple-223",)]
    assert "single" not in benchmark.DEFAULT_GROUPS


def test_light_benchmark_by_material_tells_matte_from_glossy_and_averages_each_light_set(tmp_path):
    """A Lambertian material's mirror peak is its off-peak value (1); a Phong lobe's stands far
    out. The means are per light set, over the named objects; a missing case reads '–'."""
    import torch
    study = load_script("lb_by_material", "experiments/light_benchmark/by_material.py")
    lambertian = lambda wi, wo: torch.full((len(wi), 3), 0.5 / np.pi)              # noqa: E731

    def phong(wi, wo):
        mirror = wi * torch.tensor([-1.0, -1.0, 1.0])
        return 0.1 + (mirror * wo).sum(-1, keepdim=True).clamp_min(0).expand(-1, 3) ** 200

    assert study.gloss(lambertian) == pytest.approx(1.0)
    assert study.gloss(phong) > study.GLOSSY_PEAK
    results = tmp_path / "run"
    results.mkdir()
    for group, name, label, error in [("single", "blob01", "96", 2.0), ("single", "face", "96", 4.0),
                                      ("single", "blob01", "20", 1.0), ("benchmark", "blob01", "96", 9.0)]:
        (results / f"{group}-{name}-{label}.json").write_text(json.dumps(
            {"stages": [{"stage": "network", "dir": error}, {"stage": "reversal", "dir": 50.0}]}))
    single = study.stage_errors(results, "single")
    assert single == {("blob01", "96"): 2.0, ("face", "96"): 4.0, ("blob01", "20"): 1.0}
    assert study.stage_errors(results, "single", final=True)[("face", "96")] == 50.0
    assert study.means(single, ["blob01", "face"]) == "3.00 / – / –°"
    assert study.means(single, ["blob01"]) == "2.00 / 1.00 / –°"
    assert study.means(study.stage_errors(results, "benchmark"), ["face"]) == "–"
    (results / "single-face-20.json").write_text(json.dumps(
        {"stages": [{"stage": "network", "dir": 3.0, "slant": -1.5}, {"stage": "reversal", "dir": 3.0, "slant": -0.5}]}))
    slants = study.stage_errors(results, "single", key="slant")
    assert slants == {("face", "20"): -1.5}                   # results made before the slant bias left out
    assert study.means(slants, ["face"], "+") == "– / -1.50 / –°"
    assert study.stage_errors(results, "single", final=True, key="slant") == {("face", "20"): -0.5}


def test_average_weights_takes_each_parameters_mean_in_float32_and_refuses_mismatched_weights(tmp_path):
    """Two float16 states average to their float32 mean, stored as float16; shares weigh them; a
    missing parameter, a wrong count of shares or a missing file is refused with exit status 2."""
    import torch
    study = load_script("le_average_weights", "experiments/light_estimation/average_weights.py")
    a = {"w": torch.tensor([1.0, 2048.0], dtype=torch.float16), "b": torch.zeros(2, dtype=torch.float16)}
    b = {"w": torch.tensor([3.0, 2052.0], dtype=torch.float16), "b": torch.ones(2, dtype=torch.float16)}
    mean = study.average_state([a, b], [0.5, 0.5])
    assert mean["w"].dtype == torch.float16 and mean["w"].tolist() == [2.0, 2050.0]
    assert study.average_state([a, b], [0.75, 0.25])["b"].tolist() == [0.25, 0.25]
    with pytest.raises(ValueError, match="do not have the parameters"):
        study.average_state([a, {"w": b["w"]}], [0.5, 0.5])
    with pytest.raises(ValueError, match="shares must be 2"):
        study.average_state([a, b], [1.0])

    for name, state in (("a.pt", a), ("b.pt", b)):
        torch.save({"state_dict": state, "unps_config": {"recipe": {}}, "notes": {"command": name}}, tmp_path / name)
    script = "experiments/light_estimation/average_weights.py"
    root = Path(__file__).parents[1]
    done = subprocess.run([sys.executable, script, str(tmp_path / "ab.pt"), str(tmp_path / "a.pt"),
                           str(tmp_path / "b.pt")], capture_output=True, text=True, cwd=root)
    assert done.returncode == 0, done.stderr
    saved = torch.load(tmp_path / "ab.pt", weights_only=False)
    assert saved["state_dict"]["w"].tolist() == [2.0, 2050.0] and saved["unps_config"] == {"recipe": {}}
    assert saved["notes"]["shares"] == [0.5, 0.5]
    done = subprocess.run([sys.executable, script, str(tmp_path / "x.pt"), str(tmp_path / "a.pt"),
                           str(tmp_path / "nope.pt")], capture_output=True, text=True, cwd=root)
    assert done.returncode == 2 and "no such weights" in done.stderr and not (tmp_path / "x.pt").exists()


def test_light_benchmark_records_which_weights_its_results_were_made_with(tmp_path):
    """The digest of the weights file a run reads (``checkpoint=``, ``light.checkpoint=`` for the
    normals study's estimated lights, or the shipped one) is part of what a results folder records,
    so rows of two networks never share a folder under one tag."""
    import hashlib

    from unps.lightnet.system import SHIPPED
    benchmark = load_script("lb_benchmark", "experiments/light_benchmark/benchmark.py")
    weights = tmp_path / "w.pt"
    weights.write_bytes(b"one network")
    assert benchmark.weights_used([f"checkpoint={weights}", "selfcal.steps=10"]) == \
        hashlib.sha256(b"one network").hexdigest()[:12]
    assert benchmark.weights_used(["selfcal.steps=10"]) == benchmark.weights_used(["checkpoint=null"]) == \
        hashlib.sha256(SHIPPED.read_bytes()).hexdigest()[:12]
    with pytest.raises(InputError, match="nope.pt: light-network weights not found"):
        benchmark.weights_used([f"checkpoint={tmp_path / 'nope.pt'}"])
    made = {"stages": ["reversal"], "settings": [], "weights": benchmark.weights_used([])}
    benchmark.runs.claim(tmp_path / "run", made)
    weights.write_bytes(b"the next network")
    with pytest.raises(ValueError, match="give another --tag"):
        benchmark.runs.claim(tmp_path / "run", {**made, "weights": benchmark.weights_used([f"checkpoint={weights}"])})
    normals = load_script("lb_normals", "experiments/light_benchmark/normals.py")
    assert normals.made_with("selfcal", [f"light.checkpoint={weights}"])[-1] == \
        f"light-network weights {hashlib.sha256(b'the next network').hexdigest()[:12]}"
    assert normals.made_with("estimated", [])[-1] == f"light-network weights {benchmark.weights_used([])}"
    assert normals.made_with("gt", [f"light.checkpoint={weights}"]) == [f"light.checkpoint={weights}"]
    with pytest.raises(InputError, match="gone.pt: light-network weights not found"):
        normals.made_with("selfcal", [f"light.checkpoint={tmp_path / 'gone.pt'}"])


def test_decoding_study_reads_the_shipped_soft_arg_max_as_the_network_does_and_each_other_way():
    """The study's ``soft`` reading of the eight passes is ``light=estimated``'s own estimate; a
    peak of two equal bins is read at their middle by every reading but arg-max, and a
    temperature above 1 draws a lopsided softmax toward its lesser bin."""
    import torch

    from unps.lightnet.estimate import network_lights
    from unps.lightnet.system import load_lightnet
    from unps.metrics import light_direction_mae

    decoding = load_script("lb_decoding", "experiments/light_benchmark/decoding.py")
    net, config = load_lightnet(None)
    subject = render_lambertian(shape="sphere", size=32, n_lights=10, seed=1)
    result = decoding.run_case(subject, net, config["recipe"]["resolution"])
    shipped = light_direction_mae(network_lights(subject, device="cpu")[0].directions, subject.light_directions)
    assert result["soft"]["error"] == pytest.approx(shipped, abs=1e-3)
    assert set(result) == {"intensity", *decoding.DECODINGS}
    pair = torch.full((1, 36), -1e9)
    pair[0, [20, 21]] = 0.0                                    # 12.5° and 17.5°, equally likely
    for how in ("soft", "T1.5", "vector"):
        x, _, z = decoding.read_directions({"azimuth": pair, "elevation": pair}, how)[0].tolist()
        assert np.degrees(np.arctan2(x, z)) == pytest.approx(15, abs=1e-3), how     # the azimuth
    lopsided = torch.full((1, 36), -1e9)
    lopsided[0, 20], lopsided[0, 21] = 1.0, 0.0
    angle = {how: float(decoding.read_directions({"azimuth": lopsided, "elevation": lopsided}, how)[0, 1])
             for how in ("soft", "T2", "T0.8", "argmax")}
    assert angle["argmax"] < angle["T0.8"] < angle["soft"] < angle["T2"]


def test_light_benchmark_diligent_rig_group_lights_the_same_objects_with_diligents_own_dome():
    """``--only diligent-rig``: the 24 objects as they are, under DiLiGenT's 96 lights (directions
    and intensities from ball's files) and the 20 and 12 spread over them as DiLiGenT's objects'
    sets are; cached apart, while the drawn rigs' objects keep the keys they had."""
    folder = diligent_object("pmsData/ballPNG")
    benchmark = load_script("lb_benchmark", "experiments/light_benchmark/benchmark.py")
    scenes = benchmark.scenes
    for on_rig, drawn in zip(scenes.ON_DILIGENT_RIG, scenes.OBJECTS):
        assert dataclasses.replace(on_rig, rig="drawn") == drawn and on_rig.key() != drawn.key()
    spec = {k: v for k, v in dataclasses.asdict(scenes.OBJECTS[0]).items() if k not in ("rig", "outline")}
    assert scenes.OBJECTS[0].key() == scenes.hashlib.sha256(json.dumps(
        {**spec, "version": scenes.SCENE_VERSION, "resolution": scenes.RESOLUTION, "spp": scenes.SPP,
         "bounces": scenes.BOUNCES, "camera": scenes.CAMERA_VERSION}, sort_keys=True).encode()).hexdigest()[:10]
    rig = scenes.diligent_rig(folder.parents[2])
    directions = np.loadtxt(folder / "light_directions.txt")
    np.testing.assert_array_equal(rig.directions["96"], directions)
    np.testing.assert_array_equal(rig.intensities["96"], np.loadtxt(folder / "light_intensities.txt"))
    for label in ("20", "12"):
        chosen = scenes.evenly_spread(directions, int(label))
        np.testing.assert_array_equal(rig.directions[label], directions[chosen])
    found = list(benchmark.cases(["diligent-rig"], ["96"], folder.parents[2], folder, names=["pits"]))
    assert [(group, name, label) for group, name, label, _ in found] == [("diligent-rig", "pits", "96")]


@pytest.fixture
def rendering_benchmark():
    """``experiments/light_benchmark/benchmark.py`` as a module, where the MERL fits its objects
    are painted with are at hand (skipped where not)."""
    if not (SHARED_DATA / "merl_nbrdf").is_dir():
        pytest.skip(f"MERL fits not found at {SHARED_DATA / 'merl_nbrdf'}")
    return load_script("lb_benchmark", "experiments/light_benchmark/benchmark.py")


@pytest.mark.slow
def test_light_benchmark_renders_without_interreflections_when_traced_to_two_bounces(
        rendering_benchmark, tmp_path, monkeypatch):
    """``--bounces 2``: a bowl's faces turned from a light get no light at all (they get its
    interreflections at the default), and the captures are cached apart while the default's keep
    their keys."""
    data, benchmark = SHARED_DATA, rendering_benchmark
    scenes = benchmark.scenes
    bowl = next(obj for obj in scenes.OBJECTS if obj.name == "bowl-a")
    direct_only = dataclasses.replace(bowl, bounces=2)
    assert bowl.bounces == scenes.BOUNCES > 2 and direct_only.key() != bowl.key()
    directions = np.array([[0.5, 0.3, 0.81], [-0.6, 0.1, 0.79]])
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    rig = scenes.Rig({"2": directions}, {"2": np.ones((2, 3))})
    turned_away = {}
    for obj in (bowl, direct_only):
        radiance, normals, _, mask = scenes.render_radiance(obj, data, rig)
        away = (normals[mask] @ directions.T).T < -0.05                          # (2, m)
        assert away.sum() > 100
        turned_away[obj.bounces] = radiance["2"][:, mask].mean(-1)[away]
    assert np.all(turned_away[2] == 0) and turned_away[scenes.BOUNCES].mean() > 0.005

    made = []
    monkeypatch.setattr(scenes, "make_captures", lambda obj, data, cache: made.append(obj) or {"12": tmp_path})
    monkeypatch.setattr(benchmark, "read_diligent", lambda folder, name, quantization: name)
    found = benchmark.cases(["benchmark", "single"], ["12"], tmp_path, tmp_path, names=["pits"], bounces=2)
    assert [read() for *_, read in found] == ["pits", "pits"]
    assert [obj.bounces for obj in made] == [2, 2]


@pytest.mark.slow
def test_light_benchmark_partial_outline_adds_the_pixels_an_object_covers_in_part(
        rendering_benchmark, tmp_path, monkeypatch):
    """``--outline partial``: the pixels the object covers whole are rendered as the exact
    outline renders them; the ones it covers in part are added, dimmer than the whole ones beside
    them, and masked where it covers at least half; cached apart, the exact outline's keys kept."""
    data, benchmark = SHARED_DATA, rendering_benchmark
    scenes = benchmark.scenes
    blob = scenes.OBJECTS[0]
    partial = dataclasses.replace(blob, outline="partial")
    assert blob.outline == "exact" and partial.key() != blob.key()
    directions = np.array([[0.0, 0.0, 1.0], [0.5, 0.3, 0.81]])
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    rig = scenes.Rig({"2": directions}, {"2": np.ones((2, 3))})
    exact, _, _, whole = scenes.render_radiance(blob, data, rig)
    drawn, normals, depth, mask = scenes.render_radiance(partial, data, rig)
    ring = mask & ~whole
    assert (mask >= whole).all() and ring.sum() > 50
    np.testing.assert_allclose(drawn["2"][:, whole], exact["2"][:, whole], atol=1e-3)
    assert np.all(exact["2"][:, ~whole] == 0) and (drawn["2"][:, ~mask].max(-1) > 0).sum() > 50
    assert np.isfinite(depth[mask]).all() and np.allclose(np.linalg.norm(normals[mask], axis=-1), 1, atol=1e-5)
    inner = whole & ~(-scenes.torch.nn.functional.max_pool2d(
        -scenes.torch.as_tensor(whole, dtype=scenes.torch.float32)[None], 3, 1, 1)[0].numpy() > 0.5)
    frontal = drawn["2"][0].mean(-1)
    assert frontal[ring].mean() < 0.9 * frontal[inner].mean()

    made = []
    monkeypatch.setattr(scenes, "make_captures", lambda obj, data, cache: made.append(obj) or {"12": tmp_path})
    monkeypatch.setattr(benchmark, "read_diligent", lambda folder, name, quantization: name)
    found = benchmark.cases(["benchmark", "diligent-rig"], ["12"], tmp_path, tmp_path, names=["pits"],
                            outline="partial")
    assert [read() for *_, read in found] == ["pits", "pits"]
    assert [obj.outline for obj in made] == ["partial", "partial"]


@pytest.mark.slow
def test_light_benchmark_renders_the_same_object_at_another_resolution(rendering_benchmark):
    """``--resolution``: the object at another size is the same object — its patches of material
    and its texture stretched, not drawn again — so that its image at half the size is its image
    at the default shrunk; cached apart, the default's keys kept."""
    data, benchmark = SHARED_DATA, rendering_benchmark
    scenes = benchmark.scenes
    blob = scenes.OBJECTS[0]
    half = dataclasses.replace(blob, resolution=scenes.RESOLUTION // 2)
    assert blob.resolution == scenes.RESOLUTION and half.key() != blob.key()
    rig = scenes.Rig({"1": np.array([[0.3, 0.2, 0.93]])}, {"1": np.ones((1, 3))})
    full, _, _, mask = scenes.render_radiance(blob, data, rig)
    small, _, _, small_mask = scenes.render_radiance(half, data, rig)
    assert small["1"].shape == (1, scenes.RESOLUTION // 2, scenes.RESOLUTION // 2, 3)
    side = scenes.RESOLUTION // 2
    shrunk = full["1"][0].reshape(side, 2, side, 2, 3).mean((1, 3))
    whole = mask.reshape(side, 2, side, 2).all((1, 3)) & small_mask
    relative = np.abs(small["1"][0] - shrunk)[whole].mean(-1) / shrunk[whole].mean(-1).clip(1e-3)
    assert whole.sum() > 500 and np.median(relative) < 0.05
    for text in ("63", "128.5", "big"):
        with pytest.raises(benchmark.argparse.ArgumentTypeError, match="at least 64"):
            benchmark.resolution(text)
    assert benchmark.resolution("256") == 256


@pytest.mark.parametrize("option, value, message", [
    ("--bounces", "1", "--bounces is the path tracer's longest path, at least 2 (direct light), got 1"),
    ("--room-light", "-0.01", "--room-light is a share of the captures' 99th percentile, at least 0, got -0.01"),
])
def test_light_benchmark_refuses_a_bad_option_by_name_writing_nothing(option, value, message, tmp_path, capsys,
                                                                       monkeypatch):
    benchmark = load_script("lb_benchmark", "experiments/light_benchmark/benchmark.py")
    monkeypatch.setattr(sys, "argv", ["benchmark.py", option, value, "--out", str(tmp_path / "out")])
    with pytest.raises(SystemExit) as stop:
        benchmark.main()
    assert stop.value.code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_a_rooms_light_is_the_same_in_every_captured_image_and_scales_with_the_albedo(tmp_path, monkeypatch):
    """``--room-light``: the light added is the same in each image before the lamps' intensities
    divide it, ``level`` × the captures' 99th percentile on average over the object, in
    proportion to each pixel's albedo; the cases hand over subjects with it added."""
    benchmark = load_script("lb_benchmark", "experiments/light_benchmark/benchmark.py")
    rng = np.random.default_rng(0)
    depth, normals, mask = height_field("sphere", 24, seed=0)
    lights = dome_lights(12, seed=2)
    albedo = np.where(np.arange(24)[None, :, None] < 12, 0.8, 0.2) * np.ones((24, 24, 3))
    intensities = rng.uniform(0.5, 1.5, (12, 3)).astype(np.float32)
    images = albedo[None] * np.clip(np.einsum("hwc,nc->nhw", normals, lights), 0, None)[..., None] * mask[..., None]
    subject = Subject("sphere", images.astype(np.float32), mask, lights, intensities, normals=normals)
    lit = benchmark.with_room_light(subject, 0.02)
    added = (lit.observed_images() - subject.observed_images())[:, mask]           # (12, m, 3)
    np.testing.assert_allclose(added, np.broadcast_to(added[:1], added.shape), atol=1e-6)
    p99 = np.percentile(subject.observed_images()[:, mask].mean(-1), 99)
    assert added.mean() == pytest.approx(0.02 * p99, rel=0.02)
    bright, dark = added[0, albedo[mask][:, 0] > 0.5].mean(), added[0, albedo[mask][:, 0] < 0.5].mean()
    assert bright / dark == pytest.approx(4.0, rel=0.05)
    assert np.all(lit.images[:, ~mask] == 0)
    monkeypatch.setattr(benchmark, "_cases", lambda *args: iter([("diligent", "sphere", "12", lambda: subject)]))
    (_, _, _, read), = benchmark.cases(["diligent"], ["12"], tmp_path, tmp_path, room_light=0.02)
    np.testing.assert_allclose(read().images, lit.images)


def test_lamps_study_evens_out_each_lamps_brightness_and_colour_from_its_true_intensity():
    """``lamps alike``: each image divided by its light's RGB intensity — the images a rig of
    equal white lamps would give; ``lamps white``: times that intensity's mean, brightness kept."""
    lamps = load_script("lb_lamps", "experiments/light_benchmark/lamps.py")
    subject = render_lambertian(shape="sphere", size=24, n_lights=8, seed=2)
    rng = np.random.default_rng(0)
    tinted = subject.replace(light_intensities=rng.uniform(0.4, 2.0, (8, 3)).astype(np.float32))
    alike, white = lamps.evened(tinted, keep_brightness=False), lamps.evened(tinted, keep_brightness=True)
    assert alike.light_intensities is None and white.light_intensities is None
    np.testing.assert_allclose(alike.observed_images(), tinted.images, rtol=1e-5, atol=1e-7)
    brightness = tinted.light_intensities.mean(1)[:, None, None, None]
    np.testing.assert_allclose(white.observed_images(), tinted.images * brightness, rtol=1e-5, atol=1e-7)
    seen = []
    result = lamps.run_case(tinted, lambda s: seen.append(s) or Lights(subject.light_directions, None, "x"))
    assert list(result) == list(lamps.READINGS) and seen[0] is tinted
    assert all(error == pytest.approx(0, abs=1e-3) for error in result.values())
    assert lamps.report({("diligent", "ball", "8"): result}).splitlines()[-1].split()[:3] == ["diligent", "8", "1"]


def test_reach_study_reads_each_light_against_its_zenith_under_both_rigs():
    """Light by light: zenith, error and zenith error; objects binned by the drawn rig's reach,
    lights by their own zenith, and DiLiGenT's lights read as a drawn rig's at the same zenith."""
    reach = load_script("lb_reach", "experiments/light_benchmark/reach.py")
    subject = render_lambertian(shape="sphere", size=16, n_lights=6, seed=2)
    truth = subject.light_directions
    tilted = truth.copy()
    tilted[0] = [0.0, 0.0, 1.0]                                  # one light read on the view axis
    result = reach.run_case(subject, lambda s: Lights(tilted, None, "x"))
    np.testing.assert_allclose(result["zenith"], reach.zenith_deg(truth.astype(np.float64)), atol=1e-4)
    assert result["error"][0] == pytest.approx(result["zenith"][0], abs=1e-4)
    assert result["zenith_error"][0] == pytest.approx(-result["zenith"][0], abs=1e-4)
    assert max(result["error"][1:]) < 0.01               # float32 directions: arccos near 1

    def case(zeniths, errors):
        return {"zenith": zeniths, "error": errors, "zenith_error": [0.0] * len(zeniths)}
    rows = {("benchmark", "a", "12"): case([5, 15], [1, 3]), ("diligent-rig", "a", "12"): case([15, 15], [5, 5]),
            ("benchmark", "rose", "12"): case([5, 15], [60, 60]), ("diligent-rig", "rose", "12"): case([5, 5], [60, 60])}
    assert reach.paired_objects(rows, "12") == ["a"]
    assert "0–25°        1      2.00°         5.00°" in reach.by_reach(rows)
    assert "DiLiGenT's 5.00°, DiLiGenT's lights read as drawn ones at their zenith 3.00°" in reach.by_zenith(rows)


def test_turn_share_finds_each_transform_it_is_made_of():
    turn_share = load_script("lb_turn_share", "experiments/light_benchmark/turn_share.py")
    rng = np.random.default_rng(0)
    truth = rng.normal(size=(40, 3))
    truth[:, 2] = np.abs(truth[:, 2]) + 1.0
    truth /= np.linalg.norm(truth, axis=-1, keepdims=True)
    turned = turn_share.rotated(truth, np.radians([4.0, -3.0, 0.0]))
    left = turn_share.left_after(turned, truth)
    assert left["as is"] > 3.0 and left["rotation"] < 0.01
    sheared = turn_share.sheared(truth, [0.08, -0.05])
    left = turn_share.left_after(sheared, truth)
    assert left["as is"] > 2.0 and left["shear"] < 0.01 and left["bas-relief"] > 0.5
    flattened = turn_share.bas_relief(truth, [0.1, 0.0, np.log(1.3)])
    left = turn_share.left_after(flattened, truth)
    assert left["as is"] > 2.0 and left["bas-relief"] < 0.01 and left["shear"] > 0.5


def test_frame_landscape_fits_from_each_frame_and_the_truth_and_reads_which_ends_lowest():
    """On a Lambertian sphere under 12 lights: the held fit from the eleven frames and from the
    truth, the free fit from the network and the truth; the summary reads each fit's error off its
    directions, picks the frame whose fit ends lowest, and finds the true frame's fit lower and
    nearer the truth than the network's."""
    from unps.lights.selfcal import SelfCalibration
    from unps.metrics import angular_error

    study = load_script("lb_frame_landscape", "experiments/light_benchmark/frame_landscape.py")
    subject = render_lambertian(shape="sphere", size=32, n_lights=12, seed=2)
    result = study.run_case(subject, SelfCalibration(device="cpu", steps=100, **study.HELD))
    assert len(result["fits"]) == 11 + 3
    row = study.summarise(result)
    held = f"held from {study.START}"
    truth = np.asarray(result["truth"])
    assert row["error"][held] == pytest.approx(
        angular_error(np.asarray(result["fits"][held]["directions"]), truth).mean())
    searched = [k for k in row["loss"] if k.startswith("held from") and k != "held from truth"]
    assert len(searched) == 11 and row["loss"][row["lowest"]] == min(row["loss"][k] for k in searched)
    assert row["loss"]["held from truth"] < row["loss"][held]
    assert row["error"]["held from truth"] < row["start"] and row["moved"] > 0
    text = study.report({("benchmark", "sphere", "12"): row})
    assert text.splitlines()[1].split()[:3] == ["benchmark", "sphere", "12"] and "1 cases" in text


def test_network_on_render_reads_the_held_fits_own_render_and_undoes_the_transform():
    """On a Lambertian sphere under 12 lights the network reads the held fit's render of itself
    within a few degrees of the held lights; each way of undoing its transform is scored, and the
    report's summary line counts the case."""
    from unps.lights.selfcal import SelfCalibration

    study = load_script("lb_network_on_render", "experiments/light_benchmark/network_on_render.py")
    subject = render_lambertian(shape="sphere", size=32, n_lights=12, seed=2)
    result = study.run_case(subject, SelfCalibration(device="cpu", steps=100))
    held = np.asarray(result["held"])
    assert held.shape == (12, 3) and np.allclose(np.linalg.norm(held, axis=1), 1, atol=1e-5)
    row = study.summarise(result)
    assert set(row) == {"start", "held", "read off", *study.UNDONE}
    assert 0 < row["read off"] < 5 and row["held"] < row["start"]
    assert study.report({("benchmark", "sphere", "12"): row}).splitlines()[-1].split()[:3] == ["benchmark", "12", "1"]


def test_large_capture_writes_the_ball_enlarged_unclipped_with_its_lights(tmp_path, capsys):
    """Four of ball's images at their own size: four 16-bit PNGs whose brightest value is the top
    level, the chosen lights beside them, read back as a user's folder is; bad arguments refused."""
    study = load_script("speed_large_capture", "experiments/speed/large_capture.py")
    diligent = diligent_object("pmsData/ballPNG").parents[1]
    folder = tmp_path / "capture"
    assert study.write_capture(diligent, 4, 1, folder) == (612, 512)
    assert sorted(p.name for p in folder.iterdir()) == ["000.png", "001.png", "002.png", "003.png",
                                                        "light_directions.txt"]
    assert not (tmp_path / "capture.partial").exists()
    capture = read_folder(folder, name="capture")
    ball = read_diligent_object(diligent, "ball")
    chosen = study.evenly_spread(ball.light_directions, 4)
    assert capture.images.shape == (4, 512, 612, 3)
    np.testing.assert_allclose(capture.light_directions, ball.light_directions[chosen], atol=1e-5)
    import cv2
    assert max(int(cv2.imread(str(folder / f"{k:03d}.png"), cv2.IMREAD_UNCHANGED).max()) for k in range(4)) == 65535
    for bad, says in ((["--images", "2"], "--images 2: between 3 and DiLiGenT's 96"),
                      (["--scale", "0"], "--scale 0: a whole number, 1 or more"),
                      (["--diligent", str(tmp_path)], "no pmsData/ballPNG there")):
        with pytest.raises(SystemExit):
            study.main([*bad, "--out", str(tmp_path / "out")])
        assert says in capsys.readouterr().err
    assert not (tmp_path / "out").exists()
    run = study.run_folder(tmp_path, "ball-12-x4", ["light=gt", "subject.root=/a/b"])
    assert run == tmp_path / "run-ball-12-x4-light_gt-subject.root__a_b"      # a Hydra value: no '='


def test_start_checks_prints_each_checks_peak_memory_time_and_finding(capsys):
    """The drawn dark 8-bit stack has black, nearly black and clipped pixels for the checks to find,
    and each check's line names what it found."""
    study = load_script("speed_start_checks", "experiments/speed/start_checks.py")
    stack, mask = study.dark_capture(6, 0.01)
    assert stack.shape == (6, 100, 100, 3) and stack.dtype == np.float32 and mask.mean() == 0.9
    np.testing.assert_array_equal(np.round(stack * 255), stack * 255)
    study.main(["--images", "6", "--megapixels", "0.01"])
    printed = capsys.readouterr().out
    lines = {line.split("  ")[0].strip(): line for line in printed.splitlines()}
    for check in ("clipped_values", "value_levels", "black_everywhere", "faintly_lit", "zero_ceiling",
                  "black_headroom (×4 grid)"):
        assert check in lines, printed
    assert "0.50/255" in lines["zero_ceiling"]
    for check in ("black_everywhere", "faintly_lit"):
        assert "0.00% of the object" not in lines[check], printed


def test_error_sources_sorts_pixels_into_outline_black_dark_shadowed_and_plain():
    from test_highlights import cap

    study = load_script("lb_error_sources", "experiments/light_benchmark/error_sources.py")
    size = 64
    rows, cols = np.mgrid[:size, :size].astype(np.float64)
    depth = 25 * np.exp(-((rows - 32) ** 2 + (cols - 32) ** 2) / (2 * 4.0 ** 2))   # a tall bump on a plane
    dz_dy, dz_dx = np.gradient(depth)                  # per row (y down) and per column
    normals = np.stack([-dz_dx, dz_dy, np.ones_like(depth)], -1)
    normals = (normals / np.linalg.norm(normals, axis=-1, keepdims=True)).astype(np.float32)
    lights = cap(48, 60.0).astype(np.float32)
    albedo = np.full((size, size), 0.8)
    albedo[4:14, 4:14] = 0.05                          # a dark patch
    albedo[4:14, 50:60] = 0.0                          # black in every image
    images = albedo * np.clip(np.einsum("hwc,nc->nhw", normals, lights), 0, None)
    images = (np.round(images * 255) / 255)[..., None].repeat(3, -1).astype(np.float32)
    mask = np.ones((size, size), bool)

    kind = study.pixel_kinds(images, mask, normals, lights, ring=2, dark=0.2, shadowed=0.1)
    names = np.array(study.KINDS)[kind]
    assert (names[:2] == "outline").all() and (names[:, -2:] == "outline").all()
    assert (names[4:14, 50:60] == "black").all()
    assert (names[4:14, 4:14] == "dark").all()
    from_bump = np.hypot(rows - 32, cols - 32)
    assert (names[(from_bump >= 10) & (from_bump < 12)] == "shadowed").all()   # the plane at its foot
    assert (names[from_bump < 6] == "plain").all()     # the bump itself casts on nothing nearer
    far = (from_bump > 18) & (albedo > 0.5)
    far[:2], far[-2:], far[:, :2], far[:, -2:] = False, False, False, False
    assert (names[far] == "plain").all()               # the plane far from it


def sphere_seen_from_above(reach: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """A (96, 96) mask of a sphere's pixels within ``reach`` of its centre (1: the whole
    outline) and their (m, 3) unit normals."""
    rows, cols = np.mgrid[:96, :96]
    x, y = (cols - 47.5) / 45, (47.5 - rows) / 45
    mask = x ** 2 + y ** 2 < reach ** 2
    return mask, np.stack([x, y, np.sqrt(np.clip(1 - x ** 2 - y ** 2, 0, 1))], -1)[mask]


def test_diffuse_maxima_undo_a_bas_relief_of_a_lambertian_spheres_lights():
    study = load_script("lb_diffuse_maxima", "experiments/light_benchmark/diffuse_maxima.py")
    from unps.metrics import angular_error

    mask, normals = sphere_seen_from_above()
    lights = np.random.default_rng(0).normal(size=(40, 3))
    lights[:, 2] = np.abs(lights[:, 2]) + 1.0
    lights /= np.linalg.norm(lights, axis=1, keepdims=True)
    gray = np.clip(lights @ normals.T, 0, None)                        # (n, m), shadows clamped
    p = study.bas_relief(0.3, -0.2, 1.0)
    wrong = lights @ np.linalg.inv(p)                                   # the lights under a bas-relief
    assert angular_error(wrong, lights).mean() > 4.0
    scaled = study.trimmed_scaled_normals(gray, wrong, (0.3, 0.9))
    images, found = study.diffuse_maxima(gray, scaled, mask, albedo_spread=0.05, bright=0.5)
    assert len(images) >= 20
    for plane in (False, True):
        undone = wrong @ np.linalg.inv(study.pinned_bas_relief(found, wrong[images], plane))
        assert angular_error(undone, lights).mean() < 1.0


def test_highlights_undo_a_bas_relief_of_a_glossy_spheres_lights():
    study = load_script("lb_highlights_bas_relief", "experiments/light_benchmark/highlights_bas_relief.py")
    from test_highlights import VIEW, cap, unit
    from unps.metrics import angular_error

    _, normals = sphere_seen_from_above(reach=0.9)
    lights = cap(96, 50.0)
    lit = np.clip(normals @ lights.T, 0, None).T                                  # (n, m)
    gray = 0.1 * lit + (np.clip(normals @ unit(lights + VIEW).T, 0, None).T ** 400) * (lit > 0)
    p = study.bas_relief(0.15, -0.1, 1.2)
    turned = lights @ np.linalg.inv(p)                  # the lights under a bas-relief, and their
    wrong, brightness = unit(turned), np.linalg.norm(turned, axis=1)   # intensities to match
    assert angular_error(wrong, lights).mean() > 4.0
    diffuse = dict(away_deg=25.0, min_images=8, max_misfit=0.15)
    pixels, scaled, _, peaks = study.highlight_cues(gray, wrong, brightness, **diffuse)
    assert len(pixels) >= 50
    undone = wrong @ np.linalg.inv(study.pinned_bas_relief(scaled, wrong[peaks]))
    assert angular_error(undone, lights).mean() < 1.0
    # under the true lights the premise holds: each highlight's diffuse normal is its half vector
    pixels, scaled, halves, _ = study.highlight_cues(gray, lights, np.ones(96), **diffuse)
    assert np.median(angular_error(scaled, halves)) < 2.5   # the half vector: a quarter of the spacing


def test_bas_relief_study_finds_a_known_bas_relief_and_reads_a_bowls_interreflections_by_depth():
    """The study's nearest bas-relief undoes one applied to the lights; on a bowl whose attached
    shadows hold exactly its one-bounce light, every depth scale's prediction explains nearly all
    of it (the pattern hardly tells the depth), while the scale it needs falls as the reading
    deepens and is near the albedo's own (1) at the true depth."""
    study = load_script("lb_bas_relief_left", "experiments/light_benchmark/bas_relief_left.py")
    from test_reversal import interreflected
    from unps.metrics import angular_error

    bowl = interreflected(concave=True)
    truth = bowl.light_directions.astype(np.float64)
    wrong = study.turned(truth, study.bas_relief(0.1, -0.15, 1.3))
    assert angular_error(wrong, truth).mean() > 4.0
    mu, nu, log_lam = study.nearest_bas_relief(wrong, truth)
    assert angular_error(study.turned(wrong, study.bas_relief(mu, nu, np.exp(log_lam))), truth).mean() < 0.05

    rows = study.interreflection_reading(bowl, Lights(bowl.light_directions, None, "estimated"), (0.7, 1.0, 1.4))
    assert all(r["pairs"] >= 500 and r["share"] > 0.95 for r in rows)
    scales = [r["fit_scale"] for r in rows]
    assert scales[0] > 1.5 > scales[1] > 0.9 > scales[2]


def test_mask_outline_study_reads_four_masks_and_the_networks_lights_under_each():
    """The eroded and dilated masks differ from the true one by one pixel layer; the automatic
    mask of an analytic sphere is within that layer of it; the network runs under each mask and
    the row counts what the automatic mask misses and adds."""
    study = load_script("lb_mask_outline", "experiments/light_benchmark/mask_outline.py")
    from scipy import ndimage

    sphere = render_lambertian(size=48, n_lights=12)
    found = study.masks(sphere)
    true = sphere.mask
    ring = true & ~ndimage.binary_erosion(true, border_value=1)
    assert np.array_equal(found["eroded"], true & ~ring)
    assert (found["dilated"] >= true).all() and (found["dilated"] & ~true).sum() > 0
    assert not (found["auto"] ^ true)[ndimage.binary_erosion(true, border_value=1)].any()   # the inside
    network, _ = study.benchmark.light_source([], [])
    result = study.run_case(sphere, network)
    row = study.summarise(result)
    assert all(0 <= row[f"net_{k}"] < 30 for k in study.NETWORK_MASKS) and np.isnan(row["final_true"])
    assert result["missed"]["auto"] == int((true & ~found["auto"]).sum())
    assert "auto mask off by" in study.report({("diligent", "sphere", "12"): row})


def test_flattening_read_fits_each_reading_and_reads_its_flattening_both_ways():
    """A turn about the view axis flattens the lights as the rule reads it and not as zenith
    angles; on a Lambertian sphere under 12 lights the held fit runs from the reading as read,
    never declined, and the report counts it under each reading of the flattening."""
    from scipy.spatial.transform import Rotation

    from unps.lights.selfcal import SelfCalibration, flattening

    study = load_script("lb_flattening_read", "experiments/light_benchmark/flattening_read.py")
    guess = render_lambertian(shape="sphere", size=16, n_lights=12, seed=2).light_directions.astype(np.float64)
    turned = guess @ Rotation.from_euler("z", 20, degrees=True).as_matrix().T
    assert flattening(turned, guess) > 0.5 and abs(study.zenith_flattening(turned, guess)) < 1e-9
    near = np.array([[np.sin(np.radians(2)), 0.0, np.cos(np.radians(2))]])      # 2° out, carried across
    across = np.array([[-np.sin(np.radians(8)), 0.0, np.cos(np.radians(8))]])   # the axis to 8° out
    assert study.zenith_flattening(across, near) == pytest.approx(-6.0)
    assert flattening(across, near) == pytest.approx(10.0)
    subject = render_lambertian(shape="sphere", size=32, n_lights=12, seed=2)
    result = study.run_case(subject, SelfCalibration(device="cpu", steps=100))
    assert list(result["fits"]) == ["as read"]
    fit = np.asarray(result["fits"]["as read"]["fit"])
    assert fit.shape == (12, 3) and np.allclose(np.linalg.norm(fit, axis=1), 1, atol=1e-5)
    row = study.summarise(result)["as read"]
    assert row["zenith"] == pytest.approx(study.zenith_flattening(fit, np.asarray(result["fits"]["as read"]["start"])))
    assert 0 < row["true zenith"] < 90 and row["moved"] > 0
    text = study.report({("benchmark", "sphere", "12"): {"as read": row}})
    assert text.splitlines()[1].split()[:4] == ["benchmark", "sphere", "12", "as"]
    counted = [line.split() for line in text.splitlines() if line.startswith(("slant", "zenith"))]
    assert len(counted) == 4 and sum(int(c[2]) for c in counted) == 2


def _case_json(folder: Path, case: str, network: float, start: float, final: float, limit, flattened=None,
               both: bool = False, rounds: int = 1) -> None:
    """A benchmark case's result json with the fields flattening_limits.py reads."""
    evidence = {} if flattened is None else {"flattened_deg": flattened}
    reason = "fitted as read and half turned: …" if both else "with the shared frame held: …"
    stages = [{"stage": "network", "dir": network}, {"stage": "reversal", "dir": start},
              {"stage": "selfcal", "dir": final, "reason": reason, "evidence": evidence}]
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"{case}.json").write_text(json.dumps(
        {"stages": stages, "light": {"selfcal": {"max_flattening_deg": limit, "rounds": rounds}}}))


def test_flattening_limits_pick_each_case_from_the_run_its_held_fit_falls_in(tmp_path, capsys):
    """Under a limit L a case's lights are the free run's where its held fit flattened them by no
    more than L, else the limited run's; limits below the limited run's, and runs not made as
    named, are refused."""
    study = load_script("lb_flattening_limits", "experiments/light_benchmark/flattening_limits.py")
    for case, flat, limited, free in (("benchmark-a-12", 1.2, 5.0, 5.0), ("benchmark-b-12", 1.8, 6.0, 4.0),
                                      ("benchmark-c-12", 3.5, 7.0, 12.0), ("diligent-rig-d-96", 2.5, 3.0, 4.0)):
        _case_json(tmp_path / "lim", case, 8.0, 8.0, limited, 1.5, 0.5)
        _case_json(tmp_path / "free", case, 8.0, 8.0, free, None, flat, both=case.startswith("benchmark-c"))
    study.main(["--results", str(tmp_path), "--limited", "lim", "--free", "free", "--limits", "1.5", "2", "none"])
    lines = capsys.readouterr().out.splitlines()
    headers = [i for i, line in enumerate(lines) if "cases; network" in line]
    assert [lines[i].split(" (")[0] for i in headers] == ["benchmark 12", "diligent-rig 96"]
    assert lines[-1].split()[0] == "diligent-rig-d-96"     # flattened past 1.5°, the two runs differ
    lines = lines[headers[0]:headers[1]]
    means = dict(re.match(r"  (.+?)\s+([\d.]+)°  ratio", line).groups() for line in lines if "ratio" in line)
    assert means == {"limit 1.5°": "6.00", "limit 2°": "5.33", "no limit": "7.00"}
    assert any("raised >1°:  1  >2°:  1" in line for line in lines if line.startswith("  no limit"))
    assert [line.split()[0] for line in lines if line.startswith("    ")] == ["benchmark-b-12", "benchmark-c-12"]
    assert "*" in [line for line in lines if "benchmark-c-12" in line][0]
    with pytest.raises(SystemExit):
        study.main(["--results", str(tmp_path), "--limited", "lim", "--free", "free", "--limits", "1"])
    assert "below the limited run's 1.5°" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        study.main(["--results", str(tmp_path), "--limited", "free", "--free", "lim"])
    assert "not selfcal.max_flattening_deg=null" in capsys.readouterr().err
    _case_json(tmp_path / "rounds", "benchmark-a-12", 8.0, 8.0, 5.0, 1.5, 0.5, rounds=3)
    with pytest.raises(SystemExit):
        study.main(["--results", str(tmp_path), "--limited", "rounds", "--free", "free"])
    assert "rounds: its cases were run with selfcal.rounds=[3], not 1" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        study.main(["--results", str(tmp_path), "--limited", "nowhere", "--free", "free"])
    assert f"{tmp_path / 'nowhere'}: no benchmark results there" in capsys.readouterr().err

import json
import subprocess
import sys

import numpy as np
import pytest
from hydra import compose, initialize_config_module

from unps.data.analytic import render_lambertian
from unps.data.writer import write_diligent
from unps.errors import InputError
from unps.fit import fit

OUTPUTS = {"metrics.json", "normals.npy", "normals.png", "albedo.npy", "albedo.png", "depth.npy",
           "mesh.ply", "shape.png", "error.png", "lights.txt", "lights.png", "tensorboard"}


def config(tmp_path, *overrides):
    with initialize_config_module(config_module="unps.conf", version_base="1.3"):
        return compose("fit", overrides=[f"paths.output_dir={tmp_path}", *overrides])


@pytest.mark.parametrize("method", ["woodham", "rpca"])
def test_fit_writes_every_output(tmp_path, method):
    metrics = fit(config(tmp_path, f"method={method}", "light=gt", "subject=lambertian",
                            "subject.size=32"))
    assert OUTPUTS <= {p.name for p in tmp_path.iterdir()}
    saved = json.loads((tmp_path / "metrics.json").read_text())
    assert saved["method"] == method and saved["light"] == "gt" and saved["n_images"] == 32
    assert saved["resolution"] == [32, 32]
    for key in ("normal_mae", "normal_median", "acc_11_25", "acc_30", "acc_45", "runtime_s"):
        assert np.isfinite(saved[key]) and saved[key] == pytest.approx(metrics[key])
    assert saved["normal_mae"] < 10
    normals = np.load(tmp_path / "normals.npy")
    assert normals.shape == (32, 32, 3)
    lights = np.loadtxt(tmp_path / "lights.txt")
    assert lights.shape == (32, 6)
    assert list((tmp_path / "tensorboard").glob("events.out.tfevents.*"))


def test_fit_on_a_diligent_folder_with_crop_and_downsample(tmp_path):
    write_diligent(render_lambertian("bumps", size=40, n_lights=16, seed=5), tmp_path / "objPNG")
    out = tmp_path / "run"
    metrics = fit(config(out, "subject=diligent", f"subject.root={tmp_path / 'objPNG'}",
                         "subject.crop_margin=2", "subject.downsample=2", "method=woodham", "light=gt"))
    assert metrics["subject"] == "lambertian-bumps"
    saved = json.loads((out / "metrics.json").read_text())
    assert saved["frame"]["step"] == 2 and saved["frame"]["top"] > 0
    assert np.load(out / "depth.npy").shape == tuple(saved["resolution"])


def test_uncalibrated_folder_with_light_gt_fails_before_writing(tmp_path):
    folder = tmp_path / "photos"
    write_diligent(render_lambertian(size=16, n_lights=4), folder)
    (folder / "light_directions.txt").unlink()
    out = tmp_path / "run"
    with pytest.raises(InputError, match="has no light directions, so light=gt cannot be used"):
        fit(config(out, "subject=folder", f"subject.root={folder}", "light=gt"))
    assert not out.exists()


def run_cli(*args, cwd):
    return subprocess.run([sys.executable, "-m", "unps.fit", *args], cwd=cwd, capture_output=True,
                          text=True, timeout=300)


@pytest.mark.slow
def test_cli_runs_from_any_folder_and_reports_bad_input(tmp_path):
    done = run_cli("subject=lambertian", "subject.size=24", "preset.steps=30", "preset.lr_drop_at=27",
                   f"hydra.run.dir={tmp_path / 'run'}", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "run" / "metrics.json").is_file()
    lines = [line.split("] - ", 1)[-1] for line in done.stderr.splitlines() if line.strip()]
    assert not any(a == b for a, b in zip(lines, lines[1:])), "a log line printed twice"   # two handlers
    # (the same text may come twice from two events: the robust initialisation of the reversal test
    # and of the fit, under lights that differ by less than its summary shows)
    assert not any(noise in done.stdout + done.stderr for noise in ("GPU available", "Tip:", "Training:",
                                                                     "deprecated"))
    assert "step 30/30: loss" in done.stderr and "outputs written to" in done.stderr

    bad = run_cli("subject=diligent", f"subject.root={tmp_path / 'nowhere'}",
                  f"hydra.run.dir={tmp_path / 'bad'}", cwd=tmp_path)
    assert bad.returncode == 2
    assert "nowhere: not a folder" in bad.stdout + bad.stderr
    assert "Traceback" not in bad.stdout + bad.stderr
    assert not (tmp_path / "bad" / "metrics.json").exists()


@pytest.mark.parametrize("args, culprit", [
    (["subject=folder", "method=woodham"], "this subject needs subject.root=…"),
    (["subject=lambertian", "method=woodham", "light=gt", "noise=abc"], "noise must be a number"),
])
@pytest.mark.slow
def test_cli_names_a_missing_or_malformed_setting(tmp_path, args, culprit):
    bad = run_cli(*args, f"hydra.run.dir={tmp_path / 'bad'}", cwd=tmp_path)
    assert bad.returncode == 2 and culprit in bad.stdout + bad.stderr
    assert "Traceback" not in bad.stdout + bad.stderr
    assert not (tmp_path / "bad" / "metrics.json").exists()


@pytest.mark.slow
def test_cli_multirun_sweeps_methods(tmp_path):
    done = run_cli("-m", "method=woodham,rpca", "light=gt", "subject=lambertian", "subject.size=24",
                   f"hydra.sweep.dir={tmp_path / 'sweep'}", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    methods = sorted(json.loads(p.read_text())["method"]
                     for p in (tmp_path / "sweep").glob("*/metrics.json"))
    assert methods == ["rpca", "woodham"]


@pytest.mark.slow
def test_a_killed_sweep_reruns_to_the_end_and_a_finished_one_reruns_cleanly(tmp_path):
    """Kill a two-job unps sweep after its first checkpoint; the same command finishes it (the
    killed job resumes, the other runs); run once more, every job reads out its finished fit."""
    import os
    import signal
    import time

    sweep = tmp_path / "sweep"
    command = [sys.executable, "-m", "unps.fit", "-m", "subject=lambertian", "subject.size=24",
               "light=gt", "preset.steps=200", "preset.lr_drop_at=180", "preset.update_every=20",
               "preset.width=8", "seed=0,1", f"hydra.sweep.dir={sweep}"]
    first = subprocess.Popen(command, cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                             start_new_session=True)
    deadline = time.time() + 240
    while not list(sweep.glob("*/checkpoints/last.ckpt")) and first.poll() is None and time.time() < deadline:
        time.sleep(0.2)
    assert first.poll() is None, "the sweep finished before it could be killed"
    os.killpg(first.pid, signal.SIGKILL)
    first.wait()
    assert not list(sweep.glob("*/metrics.json"))

    for attempt in ("finish", "rerun finished"):
        done = subprocess.run(command, cwd=tmp_path, capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr[-3000:]
        assert "Traceback" not in done.stdout + done.stderr
        runs = {m["seed"]: m for m in (json.loads(p.read_text()) for p in sweep.glob("*/metrics.json"))}
        assert sorted(runs) == [0, 1], attempt
    assert runs[0]["resumed_from_step"] == 200 == runs[1]["resumed_from_step"]


@pytest.mark.slow
def test_help_lists_the_groups_that_apply_and_examples(tmp_path):
    done = run_cli("--help", cwd=tmp_path)
    assert done.returncode == 0
    assert "Config groups" in done.stdout and "selfcal estimated gt refine" in done.stdout
    assert "recipe" not in done.stdout and "mimo" not in done.stdout and "Examples:" in done.stdout

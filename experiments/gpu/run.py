"""How unps uses one GPU: the paper preset's fit, the default command, training throughput, memory.

    python experiments/gpu/run.py                          # on a CUDA machine, about 5 minutes
    python experiments/gpu/run.py --device cpu --steps 5 --train-steps 2 --subjects lambertian \
        --default-subject lambertian --render-samples 4   # the same rows on a CPU, as a smoke test

Rows, each a fresh process (``python -m unps.fit`` / ``python -m unps.train``) in ``<out>/<row>``:

- ``paper-<subject>``: ``preset=paper light=gt`` (full resolution; ``--steps`` steps): fit seconds,
  its stages (steps, interreflection update, cast shadows, read-out), the normal MAE, peak GPU memory;
- ``default-<subject>``: the default uncalibrated command (``light=selfcal preset=fast``): wall
  seconds of the whole command, and its stages (light network, self-calibration, fit);
- ``train``: ``python -m unps.train recipe=paper`` for ``--train-steps`` steps (``--precisions``,
  ``--workers``, ``--threads`` set its recipe), the training data rendered on the device: samples
  per second over the run (start-up and a small validation included) and once running (after its
  first steps, validations left out), and peak GPU memory;
- ``data``: the training data's parts alone: the random draws (CPU, one process; the
  ``recipe.workers`` processes share them out), their rendering on the device one sample at a time
  and a batch at once, the loader with its workers, the network's training step;
- ``loop`` (not run by default): the training loop by hand, per step: waiting on the loader,
  rendering, the network's step; on a GPU with the loader's batches pinned and not;
- ``profile`` (not run by default): a short training run under cProfile, in this process;
- ``render`` (not run by default): the costliest device operators of rendering the training data
  a batch at once;
- ``start`` (not run by default): a fresh process's seconds before ``python -m unps.fit`` can log
  (the interpreter, torch, CUDA's start, Lightning, Hydra, unps);
- ``paper-<subject>-bf16-mixed`` (``--fit-precisions``): the paper preset with its networks in
  bfloat16.

Subjects are ``subject=`` names (DiLiGenT objects read from ``--diligent``, the folder holding
``pmsData/`` or ``pmsData_crop/``). A rerun skips rows whose
metrics.json exists.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import torch
from torch.utils.data import DataLoader

from unps.device import resolve_device
from unps.lightnet.data import LightData

DILIGENT = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "DiLiGenT"
FIT_STAGES = ("steps", "interreflection update", "cast shadows", "read-out", "robust initialisation")
DEFAULT_STAGES = ("light network", "self-calibration", "method")


def machine(device: str) -> str:
    """The GPU (or CPU) this script measures, with torch."""
    if device.startswith("cuda") and torch.cuda.is_available():
        name = torch.cuda.get_device_name(torch.device(device if ":" in device else "cuda:0"))
    else:
        name = platform.processor() or platform.machine()
    return f"{name}; {os.cpu_count()} CPU cores; torch {torch.__version__}"


def run(out: Path, module: str, *overrides: str) -> tuple[dict, float]:
    """``python -m <module> overrides…`` in a fresh process; its metrics.json and wall seconds (0 when
    the row was already there)."""
    metrics = out / "metrics.json"
    if metrics.is_file():
        return json.loads(metrics.read_text()), 0.0
    command = [sys.executable, "-m", module, *overrides, f"hydra.run.dir={out}"]
    print("  running", " ".join(command[2:]), flush=True)
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(command)} failed:\n{done.stderr[-3000:]}")
    return json.loads(metrics.read_text()), seconds


def memory(metrics: dict) -> str:
    peak = metrics.get("gpu_peak_gb")
    return "–" if peak is None else f"{peak:.1f}"


def subject_overrides(name: str, diligent: Path) -> list[str]:
    return [f"subject={name}", f"paths.diligent_dir={diligent}"]


def data_rates(device: str, samples: int, batch: int) -> tuple[float, float, float]:
    """Samples per second of the two halves of ``recipe=paper``'s training data on this machine:
    drawing as the workers draw for ``device`` (the CPU part, in one process; the ``recipe.workers``
    processes share it out), and rendering the draws on ``device`` one sample at a time and in
    batches of ``batch`` (the first of each, which starts CUDA, not timed)."""
    from unps.lightnet.synthesis import SceneBatch, render, render_batch

    cfg, data = paper_data(device)
    where = data.device
    start = time.perf_counter()
    scenes = [data.train_set.draw(index) for index in range(samples)]
    drawing = samples / (time.perf_counter() - start)
    batches = [SceneBatch.of(scenes[i:i + batch]) for i in range(0, samples, batch)]
    render_batch(batches[0], where)
    render(scenes[0], where)

    def rate(work) -> float:
        synchronize(where)
        start = time.perf_counter()
        work()
        synchronize(where)
        return samples / (time.perf_counter() - start)

    one = rate(lambda: [render(scene, where) for scene in scenes])
    batched = rate(lambda: [render_batch(pack, where) for pack in batches])
    return drawing, one, batched


def loader_rate(device: str, batches: int, workers: int | None) -> float:
    """Samples per second that ``recipe=paper``'s training loader delivers for ``device`` (its
    ``recipe.workers`` processes drawing, or ``workers``), nothing rendered: after its first batch,
    which starts the workers."""
    cfg, data = paper_data(device, *([] if workers is None else [f"recipe.workers={workers}"]))
    loader = iter(data.train_dataloader())
    next(loader)
    start = time.perf_counter()
    for _ in range(batches):
        next(loader)
    return batches * cfg.recipe.batch_size / (time.perf_counter() - start)


def step_rates(device: str, steps: int) -> dict[str, float]:
    """Samples per second of the light network's training step alone (forward, loss, backward, Adam)
    on one rendered ``recipe=paper`` batch, for each precision of ``recipe.precision``."""
    from hydra.utils import instantiate

    from unps.lightnet.synthesis import SceneBatch, render_batch
    from unps.lightnet.system import bin_losses
    from unps.train import PRECISIONS

    cfg, data = paper_data(device)
    where = data.device
    batch = render_batch(SceneBatch.of([data.train_set.draw(i) for i in range(cfg.recipe.batch_size)]), where)
    rates = {}
    for precision in PRECISIONS:
        net = instantiate(cfg.light, _partial_=True)().to(where)
        optimiser = torch.optim.Adam(net.parameters(), lr=cfg.recipe.lr)

        def step():
            with torch.autocast(where.type, dtype=torch.bfloat16, enabled=precision == "bf16-mixed"):
                logits = net(batch["images"], batch["mask"])
            loss = sum(bin_losses({k: v.float() for k, v in logits.items()}, batch["directions"],
                                  batch["intensities"]).values())
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()

        rates[precision] = cfg.recipe.batch_size / seconds_per_step(step, steps, where)
    return rates


def seconds_per_step(step, steps: int, device: torch.device) -> float:
    """Seconds that ``step()`` takes on ``device``, over ``steps`` calls after three not timed, the
    device waited for before and after."""
    for _ in range(3):
        step()
    synchronize(device)
    start = time.perf_counter()
    for _ in range(steps):
        step()
    synchronize(device)
    return (time.perf_counter() - start) / steps


def loop_breakdown(device: str, steps: int, workers: int | None, threads: int,
                   pinned: bool = True) -> dict[str, float]:
    """``recipe=paper``'s training loop by hand (no Lightning), the training process on ``threads``
    CPU threads, its loader pinning each batch (``pinned``, as training does on a GPU) or not:
    per step, ms waiting on the loader, rendering the batch and the network's step
    (forward, loss, backward, Adam), each waited for on the device, over the last half of
    ``steps`` (the batches the workers had ready at the start used up); then samples/s of
    ``steps`` more steps of the same loop, nothing waited for."""
    from hydra.utils import instantiate

    from unps.lightnet.synthesis import render_batch
    from unps.lightnet.system import bin_losses

    torch.set_num_threads(threads)
    cfg, data = paper_data(device, *([] if workers is None else [f"recipe.workers={workers}"]))
    where = data.device
    net = instantiate(cfg.light, _partial_=True)().to(where)
    optimiser = torch.optim.Adam(net.parameters(), lr=cfg.recipe.lr)

    def step(batch):
        logits = net(batch["images"], batch["mask"])
        loss = sum(bin_losses(logits, batch["directions"], batch["intensities"]).values())
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()

    def to_device(packed):   # on the CPU the workers render whole samples
        return packed if where.type == "cpu" else render_batch(packed, where)

    loader = data.train_dataloader()
    if not pinned:
        loader = DataLoader(loader.dataset, batch_size=loader.batch_size, num_workers=loader.num_workers,
                            persistent_workers=loader.persistent_workers, collate_fn=loader.collate_fn)
    loader = iter(loader)
    step(to_device(next(loader)))
    spent = {"wait": [], "render": [], "step": []}
    for _ in range(steps):
        start = time.perf_counter()
        packed = next(loader)
        taken = time.perf_counter()
        batch = to_device(packed)
        synchronize(where)
        rendered = time.perf_counter()
        step(batch)
        synchronize(where)
        for key, seconds in zip(spent, (taken - start, rendered - taken, time.perf_counter() - rendered)):
            spent[key].append(seconds)
    start = time.perf_counter()
    for _ in range(steps):
        step(to_device(next(loader)))
    synchronize(where)
    rate = steps * cfg.recipe.batch_size / (time.perf_counter() - start)
    return {**{key: 1e3 * sum(v[steps // 2:]) / len(v[steps // 2:]) for key, v in spent.items()},
            "samples_per_s": rate}


def profile_training(device: str, steps: int, workers: int | None, out: Path, top: int = 25) -> None:
    """Train ``recipe=paper`` for ``steps`` steps in this process under cProfile and print where
    the training process spends its time (its own functions, not the workers'): waiting on the
    loader shows as the queue's ``get``, on the GPU as CUDA's synchronising calls."""
    import cProfile
    import pstats

    from unps.train import train

    overrides = [f"recipe.max_steps={steps}", f"recipe.val_every={steps}", "recipe.val_samples=64",
                 f"device={device}", f"paths.output_dir={out}",
                 *([] if workers is None else [f"recipe.workers={workers}"])]
    profiler = cProfile.Profile()
    profiler.runcall(train, paper_config(*overrides))
    pstats.Stats(profiler).sort_stats("tottime").print_stats(top)


def render_profile(device: str, batches: int, top: int = 15) -> None:
    """Print the costliest device operators of rendering ``batches`` ``recipe=paper`` batches of 32
    at once (the training process's share of the training data)."""
    from torch.profiler import ProfilerActivity, profile

    from unps.lightnet.synthesis import SceneBatch, render_batch

    cfg, data = paper_data(device)
    where = data.device
    size = cfg.recipe.batch_size
    packs = [SceneBatch.of([data.train_set.draw(b * size + i) for i in range(size)]) for b in range(batches)]
    render_batch(packs[0], where)
    synchronize(where)
    activities = [ProfilerActivity.CPU] + ([ProfilerActivity.CUDA] if where.type == "cuda" else [])
    with profile(activities=activities) as trace:
        for pack in packs:
            render_batch(pack, where)
        synchronize(where)
    key = "self_cuda_time_total" if where.type == "cuda" else "self_cpu_time_total"
    print(trace.key_averages().table(sort_by=key, row_limit=top), flush=True)


def start_up(device: str) -> dict[str, float]:
    """Seconds a fresh Python process spends before ``python -m unps.fit`` can log: importing torch,
    starting CUDA on ``device`` (a tensor made there), importing Lightning, Hydra and unps's fit."""
    probe = ("import json, time; t = [time.perf_counter()]\n"
             "import torch; t.append(time.perf_counter())\n"
             f"torch.zeros(1, device={device!r}).sum().item(); t.append(time.perf_counter())\n"
             "import lightning; t.append(time.perf_counter())\n"
             "import hydra, omegaconf; t.append(time.perf_counter())\n"
             "import unps.fit, unps.pipeline.run; t.append(time.perf_counter())\n"
             "print(json.dumps([b - a for a, b in zip(t, t[1:])]))")
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    total = time.perf_counter() - start
    parts = json.loads(done.stdout.strip().splitlines()[-1])
    names = ("import torch", "CUDA's start" if device.startswith("cuda") else "first tensor",
             "import lightning", "import hydra", "import unps.fit")
    return {"interpreter": total - sum(parts), **dict(zip(names, parts))}


def fit_step_times(name: str, diligent: Path, device: str, steps: int) -> dict[str, float]:
    """ms per step of ``preset=paper light=gt``'s fit of subject ``name`` (full resolution, all its
    images, the interreflection solve and cast shadows as at step 0), without Lightning, each
    variant waited for on the device: as the fit runs it, with ``cudnn.benchmark``, and its two
    networks in bfloat16 (``preset.precision=bf16-mixed``). Prints the profiler's twelve costliest GPU
    operators of the plain step."""
    from hydra import compose, initialize_config_module
    from hydra.utils import instantiate

    from unps.inverse.fit import CROP_MARGIN, build_system

    with initialize_config_module("unps.conf", version_base="1.3"):
        cfg = compose("fit", overrides=[*subject_overrides(name, diligent), "preset=paper", "light=gt"])
    subject = instantiate(cfg.subject, _partial_=True)().crop_to_mask(CROP_MARGIN)
    preset, interreflection = instantiate(cfg.preset), instantiate(cfg.interreflection)
    where = resolve_device(device)
    system, _ = build_system(subject, subject.light_directions, preset, interreflection, False, "", None,
                             where)
    system = system.to(where)
    system.on_train_batch_start(None, 0)
    optimiser = system.configure_optimizers()["optimizer"]

    def step() -> None:
        loss = system.training_step(None, 0)
        loss.backward()
        optimiser.step()
        optimiser.zero_grad()

    def ms() -> float:
        return 1e3 * seconds_per_step(step, steps, where)

    times = {"as run": ms()}
    if where.type == "cuda":
        from torch.profiler import ProfilerActivity, profile

        with profile(activities=[ProfilerActivity.CPU, ProfilerActivity.CUDA]) as trace:
            for _ in range(5):
                step()
            synchronize(where)
        print(trace.key_averages().table(sort_by="self_cuda_time_total", row_limit=12), flush=True)
        torch.backends.cudnn.benchmark = True
        times["cudnn.benchmark"] = ms()
        torch.backends.cudnn.benchmark = False
    system.networks_in_bf16 = True
    times["preset.precision=bf16-mixed"] = ms()
    return times


def synchronising_calls(device: str, diligent: Path, out: Path, steps: int) -> list[tuple[str, int]]:
    """Where the training process and a fit wait for the GPU: ``recipe=paper`` training and
    ``preset=paper light=gt`` on cat, ``steps`` steps each, in this process under
    ``torch.cuda.set_sync_debug_mode("warn")``; each place with its count, named by the innermost
    line of unps on the stack and, in brackets, the line that waited (torch's or Lightning's)."""
    import traceback
    import warnings
    from collections import Counter

    from hydra import compose, initialize_config_module

    from unps.pipeline import fit
    from unps.train import train

    places: Counter = Counter()

    def note(message, category, filename, lineno, file=None, line=None):
        if "synchroniz" not in str(message):
            return
        stack = traceback.extract_stack()[:-1]
        ours = next((frame for frame in reversed(stack) if "/unps/" in frame.filename), None)
        waited = f"{Path(filename).name}:{lineno}"
        places[waited if ours is None else
               f"{Path(ours.filename).name}:{ours.lineno}" + ("" if ours.filename == filename else
                                                              f" ({waited})")] += 1

    with warnings.catch_warnings():
        warnings.simplefilter("always")
        warnings.showwarning = note
        watched = device.startswith("cuda")      # on a CPU: the same runs, nothing to watch
        if watched:
            torch.cuda.set_sync_debug_mode("warn")
        try:
            train(paper_config(f"recipe.max_steps={steps}", f"recipe.val_every={steps}",
                               "recipe.val_samples=32", f"device={device}",
                               f"paths.output_dir={out / 'syncs-train'}"))
            with initialize_config_module("unps.conf", version_base="1.3"):
                cfg = compose("fit", overrides=[*subject_overrides("cat", diligent), "preset=paper",
                                                "light=gt", f"preset.steps={steps}",
                                                f"preset.update_every={steps}", f"preset.lr_drop_at={steps}",
                                                f"device={device}",
                                                f"paths.output_dir={out / 'syncs-fit'}"])
            fit(cfg)
        finally:
            if watched:
                torch.cuda.set_sync_debug_mode(0)
    return places.most_common()


def paper_data(device: str, *overrides: str) -> tuple:
    """``recipe=paper``'s config (with ``overrides``) and its training data for ``device``, set up."""
    cfg = paper_config(*overrides)
    data = LightData(cfg.recipe, cfg.data, cfg.seed, device=resolve_device(device))
    data.setup("fit")
    return cfg, data


def cfg_workers(workers: int | None) -> int:
    """The training rows' worker processes: ``workers``, else ``recipe=paper``'s on this machine."""
    from unps.lightnet.data import loader_workers
    from unps.threads import available_cpus

    return loader_workers(paper_config().recipe.workers if workers is None else workers, available_cpus())


def paper_config(*overrides: str):
    from hydra import compose, initialize_config_module

    with initialize_config_module("unps.conf", version_base="1.3"):
        return compose("train", overrides=["recipe=paper", *overrides])


def synchronize(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--device", default="cuda")
    parser.add_argument("--out", type=Path, default=Path("runs/gpu"))
    parser.add_argument("--rows", nargs="+", default=list(ROWS[:4]), choices=ROWS,
                        help="which rows to run; the others (not run by default) time the training "
                             "loop's parts by hand (loop), the paper preset's step in variants "
                             "(fitstep), list where training and a fit wait for the GPU (syncs), and "
                             "print where a short training run's process spends its time (profile)")
    parser.add_argument("--subjects", nargs="+", default=["cat", "pot1"])
    parser.add_argument("--default-subject", default="cat", help="the subject of the default command")
    parser.add_argument("--steps", type=int, default=1000, help="steps of the paper-preset fits")
    parser.add_argument("--fit-precisions", nargs="+", default=["32-true"], choices=["32-true", "bf16-mixed"],
                        help="preset.precision of the paper-preset fits")
    parser.add_argument("--train-steps", type=int, default=100)
    parser.add_argument("--workers", type=int, default=None, help="recipe.workers of the training rows")
    parser.add_argument("--precisions", nargs="+", default=["32-true", "bf16-mixed"],
                        choices=["32-true", "bf16-mixed"], help="recipe.precision of the training rows")
    parser.add_argument("--threads", type=int, default=None,
                        help="recipe.threads of the training rows (the training process's CPU threads)")
    parser.add_argument("--render-samples", type=int, default=128)
    parser.add_argument("--diligent", type=Path, default=DILIGENT)
    args = parser.parse_args()
    device = [f"device={args.device}"]
    print(f"machine: {machine(args.device)}\n", flush=True)

    print("| row | seconds | normal MAE ° | peak GPU GB | where the time goes (s) |")
    print("|---|---|---|---|---|")
    schedule = [f"preset.steps={args.steps}", f"preset.lr_drop_at={max(1, args.steps * 9 // 10)}"]
    for name in args.subjects if "paper" in args.rows else ():
        for precision in args.fit_precisions:
            suffix = "" if precision == "32-true" else f"-{precision}"
            metrics, _ = run(args.out / f"paper-{name}{suffix}", "unps.fit",
                             *subject_overrides(name, args.diligent), "preset=paper", "light=gt",
                             f"preset.precision={precision}", *schedule, *device)
            stages = metrics["stage_seconds"]
            spent = ", ".join(f"{k} {stages[k]:.1f}" for k in FIT_STAGES if k in stages)
            print(f"| paper preset.precision={precision}, {name}, {args.steps} steps (fit) | "
                  f"{metrics['runtime_s']:.1f} | {metrics.get('normal_mae', float('nan')):.2f} | "
                  f"{memory(metrics)} | {spent} |", flush=True)

    if "default" in args.rows:
        name = args.default_subject
        metrics, wall = run(args.out / f"default-{name}", "unps.fit",
                            *subject_overrides(name, args.diligent), *device)
        stages = metrics["stage_seconds"]
        spent = ", ".join(f"{k} {stages[k]:.1f}" for k in DEFAULT_STAGES if k in stages)
        print(f"| default command, {name} (whole command) | {wall:.1f} | "
              f"{metrics.get('normal_mae', float('nan')):.2f} | {memory(metrics)} | {spent} |", flush=True)

    steps = args.train_steps
    workers = [] if args.workers is None else [f"recipe.workers={args.workers}"]
    workers += [] if args.threads is None else [f"recipe.threads={args.threads}"]
    for precision in args.precisions if "train" in args.rows else ():
        suffix = "" if args.threads is None else f"-threads{args.threads}"
        metrics, _ = run(args.out / f"train-{precision}{suffix}", "unps.train", "recipe=paper",
                         f"recipe.precision={precision}", f"recipe.max_steps={steps}",
                         f"recipe.val_every={steps}", "recipe.val_samples=64", *workers, *device)
        overall = metrics["steps"] * 32 / metrics["train_seconds"]
        running = metrics.get("train_samples_per_s")
        running = "–" if running is None else f"{running:.1f}"
        threads = "" if args.threads is None else f" recipe.threads={args.threads}"
        print(f"| training, recipe=paper recipe.precision={precision}{threads}, {steps} steps of 32 | "
              f"{metrics['train_seconds']:.1f} | – | {memory(metrics)} | {overall:.1f} samples/s over the "
              f"run (start-up and a validation of 64 included), {running} once running |", flush=True)

    if "data" in args.rows:
        drawing, one, batched = data_rates(args.device, args.render_samples, 32)
        print(f"| training data alone: draws in one CPU process; rendering on {args.device}, one sample at "
              f"a time and 32 at once | – | – | – | {drawing:.1f}; {one:.1f} and {batched:.1f} samples/s |",
              flush=True)
        workers = "recipe.workers" if args.workers is None else f"{args.workers} workers"
        print(f"| the training loader alone ({workers}, nothing rendered) | – | – | – | "
              f"{loader_rate(args.device, 30, args.workers):.1f} samples/s |", flush=True)
        rates = step_rates(args.device, 20)
        print(f"| the network's training step alone (batch 32) | – | – | – | "
              f"{'; '.join(f'{p} {r:.1f}' for p, r in rates.items())} samples/s |", flush=True)

    if "loop" in args.rows:
        taken, threads = cfg_workers(args.workers), args.threads or torch.get_num_threads()
        for pinned in (True, False) if args.device.startswith("cuda") else (True,):
            parts = loop_breakdown(args.device, args.train_steps, args.workers, threads, pinned)
            pinning = "" if args.device == "cpu" else f", batches {'pinned' if pinned else 'not pinned'}"
            print(f"| training loop by hand, {taken} workers, {threads} threads in the training process"
                  f"{pinning} | – | – | – | per step: waiting on the "
                  f"loader {parts['wait']:.0f} ms, rendering {parts['render']:.0f} ms, the network's step "
                  f"{parts['step']:.0f} ms; {parts['samples_per_s']:.1f} samples/s unwaited |", flush=True)

    if "fitstep" in args.rows:
        for name in args.subjects[:1]:
            steps = min(args.steps, 30)
            times = fit_step_times(name, args.diligent, args.device, steps)
            print(f"| paper preset's step alone, {name} ({steps} steps, no Lightning) | – | – | – | "
                  f"{'; '.join(f'{k} {v:.1f}' for k, v in times.items())} ms a step |", flush=True)

    if "syncs" in args.rows:
        steps = min(args.train_steps, 20)
        places = synchronising_calls(args.device, args.diligent, args.out, steps)
        print(f"| where {steps} training steps and a {steps}-step paper fit of cat wait for the GPU "
              f"| – | – | – | "
              f"{'; '.join(f'{place} ×{count}' for place, count in places) or 'nowhere'} |", flush=True)

    if "profile" in args.rows:
        profile_training(args.device, args.train_steps, args.workers, args.out / "profile")

    if "render" in args.rows:
        render_profile(args.device, 3)

    if "start" in args.rows:
        seconds = start_up(args.device)
        print(f"| a fresh process's start-up | {sum(seconds.values()):.1f} | – | – | "
              f"{', '.join(f'{k} {v:.1f}' for k, v in seconds.items())} |", flush=True)


ROWS = ("paper", "default", "train", "data", "loop", "fitstep", "syncs", "profile", "render", "start")


if __name__ == "__main__":
    main()

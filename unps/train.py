"""``python -m unps.train light=mimo``: train the light estimation network.

    python -m unps.train                           # the 2-core CPU recipe (recipe=cpu)
    python -m unps.train recipe=paper              # the paper's sizes (a GPU)
    python -m unps.train ckpt_path=<run>/checkpoints/last.ckpt   # resume, with that run's config
    python -m unps.train ckpt_path=<run>/checkpoints/last.ckpt recipe.max_steps=20000  # and extend it

Data are rendered on the fly (:class:`unps.lightnet.data.LightData`); checkpoints, TensorBoard logs
and ``metrics.json`` land in the run folder.
"""

from __future__ import annotations

import logging
import time
import warnings
from collections.abc import Sequence
from pathlib import Path

import hydra
import torch
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from unps.cli import command_line
from unps.device import describe, peak_memory_gb, resolve_device, trainer_placement
from unps.errors import InputError, exit_on_bad_input

log = logging.getLogger("unps.train")

PROGRESS = (("loss", "train/loss", "{:.3f}"), ("validation direction error", "val/direction_mae", "{:.2f}°"))
MAY_CHANGE = ("recipe.max_steps", "recipe.max_time", "device")   # on resuming: its length, where it runs
NOT_THE_RUN = ("ckpt_path", "paths.output_dir")          # where to resume from and write, not what
PRECISIONS = ("32-true", "bf16-mixed")   # recipe.precision: float32, or the network in bfloat16 (a GPU)


def override_key(override: str) -> str:
    """``recipe.max_steps`` of the command-line override ``recipe.max_steps=20000`` (or ``+…``)."""
    return override.split("=", 1)[0].lstrip("+~")


def plain(value):
    """A config value as plain Python (dicts and lists), for comparing."""
    return OmegaConf.to_container(value, resolve=True) if OmegaConf.is_config(value) else value


def resumed_config(saved: dict, cfg: DictConfig, overrides: Sequence[str]) -> DictConfig:
    """The config a run was started with, extended to the length (and moved to the device) the command
    line asks for.

    Args:
        saved: the config stored in the run's checkpoint.
        cfg: the config composed from the command line.
        overrides: the command line's overrides (``key=value``) that made ``cfg``.

    Raises:
        InputError: an override other than :data:`MAY_CHANGE` that changes the saved config;
            a resumed run keeps its data, network and optimiser.
    """
    resumed = OmegaConf.create(saved)
    changed = []
    for key in dict.fromkeys(map(override_key, overrides)):
        if key in NOT_THE_RUN:
            continue
        wanted, kept = OmegaConf.select(cfg, key), OmegaConf.select(resumed, key)
        if key in MAY_CHANGE:
            OmegaConf.update(resumed, key, wanted)
            if wanted != kept:
                log.info("resuming with %s=%s (the run had %s)", key, wanted, kept)
        elif plain(wanted) != plain(kept):
            changed.append(f"{key} ({kept} in the run, {wanted} asked)")
    if changed:
        allowed = f"{', '.join(MAY_CHANGE[:-1])} and {MAY_CHANGE[-1]}"
        raise InputError(f"{cfg.ckpt_path}: a resumed run keeps its config; only {allowed} may "
                         f"change, but the command line changes "
                         f"{', '.join(changed)}. Start a new run with init_weights= to fine-tune "
                         f"with other settings")
    return resumed


def initial_weights(net, path: str, cfg: DictConfig):
    """``net`` (the one ``cfg.light`` describes) with the weights of ``path`` to fine-tune, which
    must have the same layers; the strides may differ."""
    from unps.lightnet.system import load_lightnet, network_config

    saved_net, saved = load_lightnet(path)
    have = network_config(saved)
    wanted = OmegaConf.to_container(cfg.light, resolve=True)
    if {**have, "strides": None} != {**wanted, "strides": None}:
        raise InputError(f"{path}: its network {have} differs from light={wanted}; "
                         f"fine-tuning needs the same layers")
    net.load_state_dict(saved_net.state_dict())
    if list(have["strides"]) != list(wanted["strides"]):
        log.info("starting from the weights in %s, trained with strides %s, now %s",
                 path, list(have["strides"]), list(wanted["strides"]))
    else:
        log.info("starting from the weights in %s", path)
    return net


def resumed_run(cfg: DictConfig, overrides: Sequence[str]) -> tuple[DictConfig, int]:
    """The config to train with and the step to start from: ``cfg`` and 0 for a new run; for
    ``cfg.ckpt_path``, the config saved in that checkpoint (:func:`resumed_config`) and its step.

    Raises:
        InputError: the checkpoint is missing or is not a ``unps.train`` one.
    """
    if not cfg.ckpt_path:
        return cfg, 0
    ckpt = Path(cfg.ckpt_path).expanduser()
    if not ckpt.is_file():
        raise InputError(f"{ckpt}: checkpoint to resume from not found")
    checkpoint = torch.load(ckpt, map_location="cpu", weights_only=False)
    saved, start_step = checkpoint.get("unps_config"), checkpoint.get("global_step", 0)
    if saved is None:
        raise InputError(f"{ckpt}: not a unps.train checkpoint (no unps_config inside)")
    log.info("resuming from %s at step %d with the config saved in it", ckpt, start_step)
    cfg = OmegaConf.merge(resumed_config(saved, cfg, overrides),
                          {"paths": {"output_dir": str(Path(cfg.paths.output_dir))}, "ckpt_path": str(ckpt)})
    return cfg, start_step


def checked_precision(cfg: DictConfig) -> str:
    """``cfg.recipe.precision`` (float32 for runs saved before the option), once the seed and it
    are checked.

    Raises:
        InputError: a seed that is not a whole number, or a precision not in :data:`PRECISIONS`.
    """
    if isinstance(cfg.seed, bool) or not isinstance(cfg.seed, int):
        raise InputError(f"seed must be a whole number, got {cfg.seed!r}")
    precision = cfg.recipe.get("precision", "32-true")
    if precision not in PRECISIONS:
        raise InputError(f"recipe.precision must be one of {', '.join(PRECISIONS)}; got {precision!r}")
    return precision


def light_trainer(cfg: DictConfig, out: Path, device: torch.device, precision: str, callbacks: list):
    """The Lightning trainer of a run: validation every ``recipe.val_every`` steps, the best and
    the last checkpoints, TensorBoard in ``out``, ``callbacks`` after those."""
    import lightning as L
    from lightning.pytorch.callbacks import ModelCheckpoint
    from lightning.pytorch.loggers import TensorBoardLogger

    return L.Trainer(
        max_steps=cfg.recipe.max_steps, max_time=cfg.recipe.max_time,
        val_check_interval=cfg.recipe.val_every, check_val_every_n_epoch=None,
        default_root_dir=out, logger=TensorBoardLogger(str(out), name="tensorboard", version=""),
        callbacks=[ModelCheckpoint(dirpath=out / "checkpoints", monitor="val/direction_mae", mode="min",
                                   save_top_k=1, filename="best"),
                   ModelCheckpoint(dirpath=out / "checkpoints", save_last=True, save_top_k=0,
                                   every_n_train_steps=cfg.recipe.val_every),
                   *callbacks],
        **trainer_placement(device), precision=precision,
        log_every_n_steps=cfg.recipe.log_every,
        enable_progress_bar=False, enable_model_summary=False, deterministic=False)


def train(cfg: DictConfig, overrides: Sequence[str] = ()) -> dict:
    """Train (or resume) and return the final validation metrics.

    Args:
        cfg: the composed ``train`` config.
        overrides: the command-line overrides that composed it; on resuming, those of
            :data:`MAY_CHANGE` extend the run and any other change is refused.
    """
    import lightning as L
    from lightning.pytorch.callbacks import LearningRateMonitor
    from unps.inverse.callbacks import ProgressLog
    from unps.inverse.control import LIGHTNING_NOISE
    from unps.io.files import write_json
    from unps.lightnet.callbacks import LightSamples, SampleRate
    from unps.lightnet.data import LightData
    from unps.lightnet.synthesis import check_share
    from unps.lightnet.system import LightEstimation

    out = Path(cfg.paths.output_dir)
    cfg, start_step = resumed_run(cfg, overrides)
    precision = checked_precision(cfg)
    # .get: the configs of runs saved before the option lack it
    outline_jitter = check_share("data.outline_jitter", cfg.data.get("outline_jitter", 0.0))
    L.seed_everything(cfg.seed, workers=True, verbose=False)
    torch.set_num_threads(cfg.recipe.threads or torch.get_num_threads())
    device = resolve_device(cfg.get("device", "auto"))   # runs saved before the option lack it
    data = LightData(cfg.recipe, cfg.data, cfg.seed, start_step, device)
    data.setup("fit")   # errors in the data settings stop the run before the trainer starts
    net = instantiate(cfg.light, _partial_=True)()   # called here so errors reach the user
    if cfg.init_weights and not cfg.ckpt_path:
        net = initial_weights(net, cfg.init_weights, cfg)
    system = LightEstimation(net, lr=cfg.recipe.lr,
                             lr_milestones=tuple(cfg.recipe.lr_milestones),
                             lr_gamma=cfg.recipe.lr_gamma, soft_decode=cfg.soft_decode,
                             config=OmegaConf.to_container(cfg, resolve=True),
                             outline_jitter=outline_jitter, seed=cfg.seed)
    rate = SampleRate(skip=min(5, cfg.recipe.max_steps // 2))
    progress = ProgressLog(shown=PROGRESS, logger=log, after_validation=True)
    callbacks = [LightSamples(), LearningRateMonitor(), rate, progress]
    trainer = light_trainer(cfg, out, device, precision, callbacks)
    log.info("training %s on %s (%s), %d threads: %d steps of %d samples (%d px, %d images), at most %s; "
             "%s; run folder %s", type(net).__name__, describe(device), precision, torch.get_num_threads(),
             cfg.recipe.max_steps, cfg.recipe.batch_size, cfg.recipe.resolution, cfg.recipe.images,
             cfg.recipe.max_time or "no time limit", data.workers_note(), out)
    start = time.perf_counter()
    with warnings.catch_warnings():
        for message in LIGHTNING_NOISE:
            warnings.filterwarnings("ignore", message=message)
        trainer.fit(system, datamodule=data, ckpt_path=cfg.ckpt_path or None)
    if trainer.global_step < cfg.recipe.max_steps and not trainer.interrupted:
        log.info("stopped at step %d of %d: the time limit recipe.max_time=%s (training time in all) "
                 "was reached; to go on from the last validation's checkpoint: "
                 "python -m unps.train ckpt_path=%s recipe.max_time=<longer>",
                 trainer.global_step, cfg.recipe.max_steps, cfg.recipe.max_time,
                 out / "checkpoints" / "last.ckpt")
    metrics = {k: float(v) for k, v in trainer.callback_metrics.items()}
    metrics.update(train_seconds=time.perf_counter() - start, steps=trainer.global_step,
                   train_samples_per_s=rate.samples_per_s,
                   device=describe(device), gpu_peak_gb=peak_memory_gb(device))
    write_json(out / "metrics.json", metrics)
    return metrics


@command_line
@hydra.main(version_base="1.3", config_path="pkg://unps.conf", config_name="train")
@exit_on_bad_input
def main(cfg: DictConfig) -> None:
    import lightning.pytorch   # noqa: F401  (it sets its own logger to INFO when imported)

    from hydra.core.hydra_config import HydraConfig

    logging.getLogger("lightning.pytorch").setLevel(logging.WARNING)   # no accelerator lines, no adverts
    train(cfg, HydraConfig.get().overrides.task)


if __name__ == "__main__":
    main()

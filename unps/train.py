"""``python -m unps.train light=mimo``: train the light estimation network.

    python -m unps.train                           # the 2-core CPU recipe (recipe=cpu)
    python -m unps.train recipe=paper              # the paper's sizes (a GPU)
    python -m unps.train ckpt_path=<run>/checkpoints/last.ckpt   # resume, with that run's config

Data are rendered on the fly (:class:`unps.lightnet.data.LightData`); checkpoints, TensorBoard logs
and ``metrics.json`` land in the run folder.
"""

from __future__ import annotations

import logging
import time
import warnings
from pathlib import Path

import hydra
import torch
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from unps.errors import InputError, exit_on_bad_input

log = logging.getLogger("unps.train")

PROGRESS_EVERY = 250   # steps between progress lines
PROGRESS = (("loss", "train/loss", "{:.3f}"), ("validation direction error", "val/direction_mae", "{:.2f}°"))


def initial_weights(path: str, cfg: DictConfig):
    """The network of ``path`` to fine-tune, checked to be the one ``cfg.light`` describes."""
    from unps.lightnet.system import load_lightnet

    net, saved = load_lightnet(path)
    wanted = OmegaConf.to_container(cfg.light, resolve=True)
    if saved["light"] != wanted:
        raise InputError(f"{path}: its network {saved['light']} differs from light={wanted}; "
                         f"fine-tuning needs the same architecture")
    log.info("starting from the weights in %s", path)
    return net.train()


def train(cfg: DictConfig) -> dict:
    """Train (or resume) and return the final validation metrics."""
    import lightning as L
    from lightning.pytorch.callbacks import LearningRateMonitor, ModelCheckpoint
    from lightning.pytorch.loggers import TensorBoardLogger
    from unps.inverse.callbacks import ProgressLog
    from unps.inverse.control import LIGHTNING_NOISE
    from unps.io.files import write_json
    from unps.lightnet.callbacks import LightSamples
    from unps.lightnet.data import LightData
    from unps.lightnet.system import LightEstimation

    out = Path(cfg.paths.output_dir)
    start_step = 0
    if cfg.ckpt_path:
        ckpt = Path(cfg.ckpt_path).expanduser()
        if not ckpt.is_file():
            raise InputError(f"{ckpt}: checkpoint to resume from not found")
        checkpoint = torch.load(ckpt, map_location="cpu", weights_only=False)
        saved, start_step = checkpoint.get("unps_config"), checkpoint.get("global_step", 0)
        if saved is None:
            raise InputError(f"{ckpt}: not a unps.train checkpoint (no unps_config inside)")
        log.info("resuming from %s with the config saved in it", ckpt)
        cfg = OmegaConf.merge(OmegaConf.create(saved),
                              {"paths": {"output_dir": str(out)}, "ckpt_path": str(ckpt)})
    L.seed_everything(cfg.seed, workers=True, verbose=False)
    torch.set_num_threads(cfg.recipe.threads or torch.get_num_threads())
    data = LightData(cfg.recipe, cfg.data, cfg.seed, start_step)
    data.setup("fit")   # errors in the data settings stop the run before the trainer starts
    net = instantiate(cfg.light)
    if cfg.init_weights and not cfg.ckpt_path:
        net = initial_weights(cfg.init_weights, cfg)
    system = LightEstimation(net, lr=cfg.recipe.lr,
                             lr_milestones=tuple(cfg.recipe.lr_milestones),
                             lr_gamma=cfg.recipe.lr_gamma, soft_decode=cfg.soft_decode,
                             config=OmegaConf.to_container(cfg, resolve=True))
    trainer = L.Trainer(
        max_steps=cfg.recipe.max_steps, max_time=cfg.recipe.max_time,
        val_check_interval=cfg.recipe.val_every, check_val_every_n_epoch=None,
        default_root_dir=out, logger=TensorBoardLogger(str(out), name="tensorboard", version=""),
        callbacks=[ModelCheckpoint(dirpath=out / "checkpoints", save_last=True,
                                   monitor="val/direction_mae", mode="min", save_top_k=1,
                                   filename="best"),
                   LightSamples(), LearningRateMonitor(), ProgressLog(PROGRESS_EVERY, PROGRESS, log)],
        accelerator="auto", devices=1, log_every_n_steps=cfg.recipe.log_every,
        enable_progress_bar=False, enable_model_summary=False, deterministic=False)
    log.info("training %s on %d threads: %d steps of %d samples (%d px, %d images), at most %s; "
             "run folder %s", type(net).__name__, torch.get_num_threads(), cfg.recipe.max_steps,
             cfg.recipe.batch_size, cfg.recipe.resolution, cfg.recipe.images,
             cfg.recipe.max_time or "no time limit", out)
    start = time.perf_counter()
    with warnings.catch_warnings():
        for message in LIGHTNING_NOISE:
            warnings.filterwarnings("ignore", message=message)
        trainer.fit(system, datamodule=data, ckpt_path=cfg.ckpt_path or None)
    metrics = {k: float(v) for k, v in trainer.callback_metrics.items()}
    metrics.update(train_seconds=time.perf_counter() - start, steps=trainer.global_step)
    write_json(out / "metrics.json", metrics)
    return metrics


@hydra.main(version_base="1.3", config_path="pkg://unps.conf", config_name="train")
@exit_on_bad_input
def main(cfg: DictConfig) -> None:
    import lightning.pytorch   # noqa: F401  (it sets its own logger to INFO when imported)

    logging.getLogger("lightning.pytorch").setLevel(logging.WARNING)   # no accelerator lines, no adverts
    train(cfg)


if __name__ == "__main__":
    main()

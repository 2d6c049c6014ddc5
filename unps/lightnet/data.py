"""The light network's training and validation data as one LightningDataModule."""

from __future__ import annotations

import logging

import lightning as L
import torch
from torch.utils.data import DataLoader, Dataset

from unps.errors import InputError
from unps.lightnet.materials import MaterialBank
from unps.lightnet.rig import Camera
from unps.lightnet.meshes import mesh_views
from unps.lightnet.synthesis import LightDataset, Scene, SceneBatch, render_batch
from unps.threads import available_cpus

VALIDATION_SEED_OFFSET = 1_000_003   # validation stacks never share a (seed, index) with training

log = logging.getLogger(__name__)


class LightData(L.LightningDataModule):
    """Stacks rendered on the fly: a training set that starts where a resumed run left off, and a
    fixed held-out validation set.

    Args:
        recipe: ``resolution``, ``images``, ``batch_size``, ``max_steps``, ``val_samples``,
            ``workers`` (the ``recipe=`` group).
        data: ``meshes_dir``, ``views_per_mesh``, ``lights_per_shape``, ``max_zenith_deg``,
            ``materials``, ``mesh_fraction``, ``texture``, ``perturbation``, ``saturation``,
            ``shapes``, ``layouts``, ``paint``, ``second_material``, ``interreflection``,
            ``narrowed_intensities``, ``camera`` (the ``data`` node of ``unps/conf/train.yaml``).
            ``recipe.workers`` null takes :func:`loader_workers` of this machine's CPUs.
        seed: the run's seed.
        start_step: the step training resumes from; its first ``start_step · batch_size`` items
            were seen before.
        device: where the stacks are rendered. On the CPU, whole samples come from
            ``recipe.workers`` worker processes; on a GPU the workers make only each sample's
            random draws (:meth:`LightDataset.draw`, the camera noise left to the GPU), packed
            per batch (:class:`~unps.lightnet.synthesis.SceneBatch`), and the training process
            renders each batch there in one pass as it arrives
            (:meth:`transfer_batch_to_device`, :func:`~unps.lightnet.synthesis.render_batch`).
    """

    def __init__(self, recipe, data, seed: int, start_step: int = 0,
                 device: torch.device = torch.device("cpu")):
        super().__init__()
        self.recipe, self.data, self.seed, self.start_step = recipe, data, seed, start_step
        self.device = device
        self.workers = loader_workers(recipe.workers, available_cpus())
        self.train_set: LightDataset | None = None
        self.val_set: LightDataset | None = None

    def setup(self, stage: str | None = None) -> None:
        if self.train_set is not None:
            return
        recipe, data = self.recipe, self.data
        meshes = (mesh_views(data.meshes_dir, recipe.resolution, data.views_per_mesh, self.seed)
                  if data.meshes_dir else None)
        # shapes, layouts, paint, second_material, interreflection, narrowed_intensities, room_light,
        # camera:
        # .get, as the configs of older runs lack them
        common = dict(resolution=recipe.resolution, images=recipe.images,
                      lights_per_shape=data.lights_per_shape, max_zenith_deg=data.max_zenith_deg,
                      materials=MaterialBank(**data.materials), meshes=meshes,
                      mesh_fraction=data.mesh_fraction, texture=data.texture,
                      perturbation=data.perturbation, saturation=data.saturation,
                      shapes=data.get("shapes"), layouts=data.get("layouts"),
                      paint=data.get("paint", 0.0), second_material=data.get("second_material", 0.0),
                      interreflection=data.get("interreflection", 0.0),
                      narrowed_intensities=data.get("narrowed_intensities", 0.0),
                      room_light=data.get("room_light", 0.0),
                      camera=camera(data.get("camera")), device=self.device)
        done = self.start_step * recipe.batch_size
        remaining = max(recipe.max_steps * recipe.batch_size - done, recipe.batch_size)
        self.train_set = LightDataset(length=remaining, seed=self.seed, offset=done, **common)
        self.val_set = LightDataset(length=recipe.val_samples, seed=self.seed + VALIDATION_SEED_OFFSET,
                                    **common)

    def _loader(self, dataset: LightDataset) -> DataLoader:
        workers = self.workers
        if self.device.type == "cpu":
            return DataLoader(dataset, batch_size=self.recipe.batch_size, num_workers=workers,
                              persistent_workers=workers > 0)
        return DataLoader(Draws(dataset), batch_size=self.recipe.batch_size, num_workers=workers,
                          persistent_workers=workers > 0, collate_fn=SceneBatch.of,
                          pin_memory=torch.cuda.is_available())   # SceneBatch.pin_memory

    def transfer_batch_to_device(self, batch, device: torch.device, dataloader_idx: int):
        """A batch of draws (device path, a :class:`SceneBatch`) rendered on ``device``; a rendered
        batch moved there."""
        if self.device.type == "cpu":
            return super().transfer_batch_to_device(batch, device, dataloader_idx)
        return render_batch(batch, device)

    def workers_note(self) -> str:
        """Where the stacks are rendered, for the log."""
        if self.device.type != "cpu":
            return f"training data drawn in {self.workers} worker process(es) and rendered on {self.device}"
        return f"training data rendered in {self.workers} worker process(es)"

    def train_dataloader(self) -> DataLoader:
        return self._loader(self.train_set)

    def val_dataloader(self) -> DataLoader:
        return self._loader(self.val_set)


def loader_workers(requested: int | None, cpus: int) -> int:
    """The training loader's worker processes: ``requested`` (``recipe.workers``), or for None every
    CPU but two, which the training process and its loader's thread take.

    Example:
        >>> loader_workers(None, 16), loader_workers(None, 2), loader_workers(3, 16)
        (14, 0, 3)

    Raises:
        InputError: a negative or fractional ``requested``.
    """
    if requested is None:
        return max(cpus - 2, 0)
    if isinstance(requested, bool) or not isinstance(requested, int) or requested < 0:
        raise InputError(f"recipe.workers must be a whole number >= 0 (or null: every CPU but two), "
                         f"got {requested!r}")
    return requested


class Draws(Dataset):
    """A :class:`LightDataset`'s samples as their draws (:class:`~unps.lightnet.synthesis.Scene`),
    not yet rendered."""

    def __init__(self, samples: LightDataset):
        self.samples = samples

    def __len__(self) -> int:
        return len(self.samples)

    def __getitem__(self, index: int) -> Scene:
        return self.samples.draw(index)


def camera(settings) -> Camera | None:
    """The simulated camera of ``data.camera`` (None: the paper's perturbation instead)."""
    if settings is None:
        return None
    fields = dict(settings)
    return Camera(**{**fields, "exposure": tuple(fields["exposure"]), "formats": dict(fields["formats"])})

"""The per-subject optimisation's hyper-parameters (``preset.*``), checked on construction."""

from __future__ import annotations

from dataclasses import dataclass

from unps.errors import InputError

RESIDUALS = ("absolute", "sqrt", "relative", "albedo")


@dataclass(frozen=True)
class Schedule:
    """The optimisation's hyper-parameters (supplementary §2.2 unless noted).

    Attributes:
        steps: Adam steps (1000).
        lr: learning rate (8e-4).
        normal_lr: learning rate of the estimation branch ξ_f, ξ_n1; None = ``lr`` (the paper
            used 8e-5 on its own dataset).
        lr_drop_at: the step after which every learning rate is divided by 10 (900).
        input_noise_var: variance of the Gaussian noise added to f_sp's image input (0.1, the
            supplementary's; the fast preset's 0.05), on images scaled to [0, ~1] (their 99th
            percentile over the object is 1).
        images_per_step: images rendered per step; None = all of them.
        pixel_keep: fraction of object pixels in each step's loss (Taniai & Maehara: 0.1).
        prior_weight: weight of the prior ‖N_o − N_init‖² toward the robust initialisation.
        prior_steps: the prior holds for the first this many steps.
        update_every: depth and the interreflection kernel are rebuilt from N_o this often (100).
        residual: how each pixel's L1 residual enters the loss: ``absolute`` (the paper's),
            ``relative``, divided by the pixel's mean brightness over the images (floored at a
            tenth of the object's median), so that dark materials weigh as much as bright ones,
            ``sqrt``, divided by the square root of that brightness (half-way, in log terms), or
            ``albedo``, divided by the initialisation's albedo (floored alike): the residual in
            shading units, which weighs a dark material up but not a pixel the shape keeps dark.
        censor_black: beyond the paper, a value read as 0 in a quantised stack (an 8-bit
            capture's grazing lights and dark materials) says only that the light there was
            below the stack's first level: the loss charges a rendering only for what it puts
            above that level (on the working grid, above the share of the block's pixels that
            read 0 times that level, :func:`unps.inverse.grids.black_headroom`), not for any
            light at all, except on the pixels read as 0 in most of their images (a dark
            material). Read as plain zeros, they pull the normals away from the lights that
            graze them: steeper than the truth.
        dark_hold: beyond the paper, the weight of a pull ‖N_o − N_init‖² that stays on after
            ``prior_steps`` on the pixels of a dark material, each by its
            :func:`unps.inverse.system.dark_weight`: there the images hardly pin the normals, and
            once the prior ends the reflectance network can explain them with any. 0: off.
        highlight_hold: beyond the paper, the weight of a pull ‖N_o − h‖² on the working grid's
            pixels lit by a specular highlight (:func:`unps.inverse.highlights.highlight_normals`),
            h the half vector of the view and the light of the pixel's brightest image, for every
            step: the L1 loss takes those images for outliers, and the network shared with the
            pixels around them carries the half vector to them (1: pinned; the light benchmark's
            glossy objects, ``experiments/light_benchmark/README.md``, "The fit held to its
            highlights"). 0: off, as in the paper.
        hold_light_frame: beyond the paper, when the fit learns the lights (``light.refine``), it
            learns no rotation that turns them all together
            (:func:`unps.inverse.system.without_common_rotation`): the frame is the light
            stages', and a frame turned with the normals renders the diffuse part of the images
            alike, so the loss hardly tells it and the lights drift in it.
    """

    steps: int = 1000
    lr: float = 8e-4
    normal_lr: float | None = None
    lr_drop_at: int = 900
    input_noise_var: float = 0.1
    images_per_step: int | None = None
    pixel_keep: float = 0.1
    prior_weight: float = 0.1
    prior_steps: int = 50
    update_every: int = 100
    residual: str = "absolute"
    censor_black: bool = True
    dark_hold: float = 0.1
    highlight_hold: float = 1.0
    hold_light_frame: bool = True

    def __post_init__(self):
        if self.residual not in RESIDUALS:
            raise InputError(f"preset.residual must be one of {', '.join(RESIDUALS)}, got {self.residual!r}")
        whole = {"steps": 1, "update_every": 1, "lr_drop_at": 0, "prior_steps": 0}
        for name, least in whole.items():
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < least:
                raise InputError(f"preset.{name} must be a whole number >= {least}, got {value!r}")
        if self.images_per_step is not None and (not isinstance(self.images_per_step, int)
                                                 or self.images_per_step < 1):
            raise InputError(f"preset.images_per_step must be a whole number >= 1 or null (all "
                             f"images), got {self.images_per_step!r}")
        positive = {"lr": self.lr, "normal_lr": self.normal_lr, "pixel_keep": self.pixel_keep}
        for name, value in positive.items():
            if value is not None and not (isinstance(value, (int, float)) and value > 0):
                raise InputError(f"preset.{name} must be a number > 0, got {value!r}")
        if self.pixel_keep > 1:
            raise InputError(f"preset.pixel_keep is a share of the object's pixels, in (0, 1]; got "
                             f"{self.pixel_keep}")
        for name in ("hold_light_frame", "censor_black"):
            if not isinstance(getattr(self, name), bool):
                raise InputError(f"preset.{name} must be true or false, got {getattr(self, name)!r}")
        for name in ("input_noise_var", "prior_weight", "dark_hold", "highlight_hold"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and value >= 0):
                raise InputError(f"preset.{name} must be a number >= 0, got {value!r}")

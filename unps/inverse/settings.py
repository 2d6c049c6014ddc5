"""The settings of ``method=unps``: network sizes and schedule (``preset=fast|paper``) and the
interreflection model (``interreflection=nayar|…|off``), as the config groups give them."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import torch

from unps.device import native_bfloat16
from unps.errors import InputError
from unps.inverse.schedule import Schedule

INITS = ("robust", "least_squares")
PRECISIONS = ("auto", "32-true", "bf16-mixed")
READ_OUT_FIELDS = ("continue_black", "continue_held", "continue_outline", "refine_pixels", "highlights")
"""The :class:`Preset` fields used only after the last step, to read the normals out of the fitted
networks: a finished fit's checkpoint is read out again under other values of them."""


@dataclass(frozen=True)
class Preset:
    """Network sizes, working resolution and schedule (``preset=fast|paper``).

    Attributes:
        name: label.
        width, depth, first_kernel: the normal network (:class:`NormalNet`).
        reflectance_width, reflectance_depth, reflectance_branch: f_sp (:class:`ReflectanceNet`).
        feature_scale_width: beyond the paper, f_sp's first layer takes the normal network's
            global features scaled by ``feature_scale_width / width`` (never up;
            :meth:`feature_scale`), so that they weigh in f_sp as a network this wide's do against
            the image. None: unscaled (Taniai & Maehara). Unscaled, the 384-wide network's features
            drown f_sp's image input, whose reflectance then varies too little between images,
            and the normals of the smooth ball come out too steep (experiments/calibrated).
        batch_norm: batch normalisation in both networks (Taniai & Maehara's code).
        init: the start N_init and albedo P: ``robust`` (the paper's low-rank initialisation,
            :func:`unps.solvers.rpca.robust_init`) or ``least_squares`` (Woodham's, on every
            pixel as captured: :func:`unps.solvers.woodham.woodham`).
        max_pixels: object pixels on the working grid; larger subjects are block-averaged by the
            smallest whole factor that fits, and the normals upsampled back. None = full resolution.
        cast_shadows: beyond the paper, render the shadows that the fitted surface casts, from its
            depth at each update (:func:`unps.inverse.system.visibility`).
        continue_black: beyond the paper, the read-out's normals of pixels black in every image
            (:func:`unps.data.checks.black_everywhere`: the images hold no shading there), and of
            those nearly so whose few values do not follow Lambert's cosine and that no highlight
            lights (:func:`unps.data.checks.faintly_lit`, :func:`unps.inverse.fit.unshaded`), are
            those of the surface continued from the pixels around them
            (:func:`unps.geometry.continue_surface`), not the normal network's guess.
        continue_held: beyond the paper, the read-out's normals of the pixels of a dark material
            that the fit held toward N_init (``dark_hold``; :func:`unps.inverse.fit.held_from_solve`)
            and no highlight lights are taken this share of the way (in [0, 1]; 0: not at all) to
            the surface continued across them: their images pin them no better than N_init does.
        continue_outline: beyond the paper, the surface continued across black and held pixels
            turns away from the camera where it reaches the object's outline, as the seen part of
            the outline does (:func:`unps.geometry.outline_normals`: the occluding contour); false:
            the least-curved surface runs on up to the outline.
        refine_pixels: beyond the paper, each pixel's normal on the subject's grid is solved
            against its own images under the fitted reflectance
            (:func:`unps.inverse.pixels.refine_pixel_normals`), from the fit's normals (upsampled
            from a coarser working grid), unless the images are too noisy for it
            (:data:`unps.inverse.pixels.NOISE_LIMIT`).
        highlights: beyond the paper, pixels lit by a specular highlight (their brightest image far
            above the rest, their images not Lambertian, the lights dense) take the highlight's
            half vector for their normal (:func:`unps.inverse.highlights.highlight_normals`): the
            fit's L1 loss takes those images for outliers and leaves dark glossy materials loose.
        precision: ``32-true``; ``bf16-mixed``, the two networks' convolutions in bfloat16
            (autocast; a GPU's tensor cores), their outputs and every other step of the rendering
            and the loss in float32; ``auto``, bf16-mixed where the device has bfloat16
            hardware (a CUDA GPU, a CPU with AMX or AVX512-BF16) and 32-true elsewhere
            (:meth:`network_precision`).
        schedule: the optimisation's :class:`Schedule`.
    """

    name: str = "paper"
    width: int = 384
    depth: int = 4
    first_kernel: int = 3
    reflectance_width: int = 16
    reflectance_depth: int = 3
    reflectance_branch: int = 3
    feature_scale_width: int | None = 48
    max_pixels: int | None = None
    cast_shadows: bool = True
    batch_norm: bool = True
    init: str = "robust"
    continue_black: bool = True
    continue_held: float = 0.25
    continue_outline: bool = True
    refine_pixels: bool = True
    highlights: bool = True
    precision: str = "auto"
    schedule: Schedule = Schedule()

    def __post_init__(self):
        if isinstance(self.reflectance_branch, bool) or not isinstance(self.reflectance_branch, int) \
                or self.reflectance_branch < 1:
            raise InputError(f"preset.reflectance_branch must be a whole number >= 1, got "
                             f"{self.reflectance_branch!r}")
        if self.feature_scale_width is not None and (
                isinstance(self.feature_scale_width, bool) or not isinstance(self.feature_scale_width, int)
                or self.feature_scale_width < 1):
            raise InputError(f"preset.feature_scale_width must be a whole number >= 1 or null, got "
                             f"{self.feature_scale_width!r}")
        if self.init not in INITS:
            raise InputError(f"preset.init must be one of {', '.join(INITS)}, got {self.init!r}")
        if isinstance(self.continue_held, bool) or not isinstance(self.continue_held, (int, float)) \
                or not 0 <= self.continue_held <= 1:
            raise InputError(f"preset.continue_held must be a share in [0, 1], got {self.continue_held!r}")
        if self.precision not in PRECISIONS:
            raise InputError(f"preset.precision must be one of {', '.join(PRECISIONS)}, "
                             f"got {self.precision!r}")
        for name in ("batch_norm", "cast_shadows", "continue_black", "continue_outline", "refine_pixels",
                     "highlights"):
            if not isinstance(getattr(self, name), bool):
                raise InputError(f"preset.{name} must be true or false, got {getattr(self, name)!r}")

    def feature_scale(self) -> float:
        """f_sp's factor on the global features (:class:`unps.inverse.networks.ReflectanceNet`).

        >>> Preset(width=384, feature_scale_width=48).feature_scale()
        0.125
        >>> Preset(width=48).feature_scale(), Preset(feature_scale_width=None).feature_scale()
        (1.0, 1.0)
        """
        if self.feature_scale_width is None:
            return 1.0
        return min(1.0, self.feature_scale_width / self.width)

    def network_precision(self, device: torch.device) -> str:
        """``precision`` for a fit on ``device``: ``auto`` made ``bf16-mixed`` where the device
        computes bfloat16 convolutions in hardware (:func:`unps.device.native_bfloat16`: a CUDA
        GPU, where the paper preset's fit of cat and pot1 took 15 % less time at 0.05-0.12° lower
        error; a CPU with AMX or AVX512-BF16, where the fast preset's took 0.60-0.71× the time at
        the same error on 24 unseen objects) and ``32-true`` elsewhere (a 2-core CPU without
        either, which emulates bfloat16, ran it 6× slower)."""
        if self.precision != "auto":
            return self.precision
        return "bf16-mixed" if native_bfloat16(device) else "32-true"

    @classmethod
    def from_config(cls, **fields) -> Preset:
        """From the flat ``preset`` config node: :class:`Schedule`'s keys go to ``schedule``."""
        timing = {f.name for f in dataclasses.fields(Schedule)}
        return cls(**{k: v for k, v in fields.items() if k not in timing},
                   schedule=Schedule(**{k: v for k, v in fields.items() if k in timing}))

    def fields(self) -> dict:
        """The flat fields again, as the config node has them."""
        flat = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "schedule"}
        return {**flat, **dataclasses.asdict(self.schedule)}

    def fit_fields(self) -> dict:
        """:meth:`fields` less :data:`READ_OUT_FIELDS`: what the fit's steps depend on, and so what
        a checkpoint must have been made with to be resumed (:func:`unps.inverse.control.fingerprint`).

        >>> sorted(set(Preset().fields()) - set(Preset().fit_fields())) == sorted(READ_OUT_FIELDS)
        True
        """
        return {name: value for name, value in self.fields().items() if name not in READ_OUT_FIELDS}


@dataclass(frozen=True)
class InterreflectionModel:
    """How ``method=unps`` renders interreflections (``interreflection=nayar|…|off``).

    Attributes:
        name: label.
        enabled: render with Nayar's pseudo-normals N_ny (else with N_o).
        downsample: facet grid factor of the kernel.
        occlusion: visibility between facets in the kernel.
        albedo: the object's median diffuse reflectance, to scale P; None takes the robust
            initialisation's albedo as a reflectance.
    """

    name: str = "nayar"
    enabled: bool = True
    downsample: int = 4
    occlusion: bool = True
    albedo: float | None = None

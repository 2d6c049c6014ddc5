"""The capture rig of the light network's training data: where the lights stand, and the camera.

Light layouts copy real rigs: a uniform cap, a dome (a jittered grid in the image plane's light
components), rings at fixed zeniths, and a panel (a flat board of lamps facing the object, as
DiLiGenT's LEDs stand: a rectangular grid in the lights' tangents). The camera exposes, adds
noise, saturates at its full scale and stores the result the way files store it (8-bit rounded,
8-bit truncated from a 16-bit source, 16-bit, float), so the network sees values as unps reads
them from such files.

Frame: x right, y up, z toward the camera.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import torch

from unps.device import to_device

LAYOUTS = ("cap", "dome", "ring", "panel")
FORMATS = ("float", "round8", "floor8", "round16")


def turned(points: torch.Tensor, angle: float) -> torch.Tensor:
    """(m, 2) points turned counter-clockwise by ``angle`` radians about the origin."""
    rotation = torch.tensor([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    return points @ rotation.T


def cap_lights(count: int, max_zenith_deg: float, generator: torch.Generator) -> torch.Tensor:
    """(count, 3) unit directions uniform over the cap within ``max_zenith_deg`` of +z."""
    z = 1 - torch.rand(count, generator=generator) * (1 - math.cos(math.radians(max_zenith_deg)))
    phi = 2 * math.pi * torch.rand(count, generator=generator)
    s = torch.sqrt(1 - z ** 2)
    return torch.stack([s * torch.cos(phi), s * torch.sin(phi), z], -1)


def dome_lights(count: int, max_zenith_deg: float, generator: torch.Generator) -> torch.Tensor:
    """(count, 3) directions on a jittered square grid of (l_x, l_y), as on DiLiGenT's dome: the
    grid spans ±sin(θ) with θ between a third of ``max_zenith_deg`` and all of it, turned by a
    random angle; the first ``count`` grid points in a random order."""
    u = lambda *shape: torch.rand(*shape, generator=generator)    # noqa: E731
    side = math.ceil(math.sqrt(count))
    reach = math.sin(math.radians(max_zenith_deg * (1 + 2 * float(u(1))) / 3)) / math.sqrt(2)
    t = torch.linspace(-reach, reach, side)
    grid = torch.stack(torch.meshgrid(t, t, indexing="xy"), -1).reshape(-1, 2)
    grid = grid + (u(len(grid), 2) - 0.5) * (2 * reach / max(side - 1, 1)) * 0.3
    planar = turned(grid, 2 * math.pi * float(u(1)))[torch.randperm(len(grid), generator=generator)[:count]]
    norm = planar.norm(dim=-1, keepdim=True)
    planar = planar * (norm.clamp(max=0.999) / norm.clamp_min(1e-9))   # the jitter may reach past 90°
    return torch.cat([planar, torch.sqrt(1 - (planar ** 2).sum(-1, keepdim=True))], -1)


def ring_lights(count: int, max_zenith_deg: float, generator: torch.Generator) -> torch.Tensor:
    """(count, 3) directions on one to three rings, each at a zenith between 10° and
    ``max_zenith_deg`` with evenly spaced azimuths (a random phase each)."""
    u = lambda *shape: torch.rand(*shape, generator=generator)    # noqa: E731
    rings = int(1 + 3 * float(u(1)))
    sizes = [count // rings + (i < count % rings) for i in range(rings)]
    out = []
    for size in sizes:
        zenith = math.radians(10 + (max_zenith_deg - 10) * float(u(1)))
        phi = 2 * math.pi * (torch.arange(size) / size + float(u(1)))
        out.append(torch.stack([math.sin(zenith) * torch.cos(phi), math.sin(zenith) * torch.sin(phi),
                                torch.full((size,), math.cos(zenith))], -1))
    return torch.cat(out)[torch.randperm(count, generator=generator)]


def panel_lights(count: int, max_zenith_deg: float, generator: torch.Generator) -> torch.Tensor:
    """(count, 3) directions to lamps on a flat board facing the object, as DiLiGenT's 12 × 8 LEDs:
    a rectangular grid of rows × columns (their ratio between ½ and 2) evenly spaced in
    (l_x / l_z, l_y / l_z), its corners at a zenith between a third of ``max_zenith_deg`` and
    all of it, its centre off the view axis by up to a tenth of its reach, turned by up to 10°
    and jittered by 5 % of a spacing; the first ``count`` grid points in a random order."""
    u = lambda *shape: torch.rand(*shape, generator=generator)    # noqa: E731
    aspect = 2 ** (2 * float(u(1)) - 1)
    columns = max(1, round(math.sqrt(count * aspect)))
    rows = math.ceil(count / columns)
    reach = math.tan(math.radians(max_zenith_deg * (1 + 2 * float(u(1))) / 3))
    spacing = reach / max(math.hypot(columns - 1, rows - 1) / 2, 0.5)
    x = (torch.arange(columns) - (columns - 1) / 2) * spacing
    y = (torch.arange(rows) - (rows - 1) / 2) * spacing
    grid = torch.stack(torch.meshgrid(x, y, indexing="xy"), -1).reshape(-1, 2)
    grid = grid + (u(len(grid), 2) - 0.5) * 0.1 * spacing
    tangents = turned(grid, math.radians(20 * float(u(1)) - 10)) + (u(2) - 0.5) * 0.2 * reach
    tangents = tangents[torch.randperm(len(grid), generator=generator)[:count]]
    return torch.nn.functional.normalize(torch.cat([tangents, torch.ones(count, 1)], -1), dim=-1)


def draw_lights(weights: dict[str, float], count: int, max_zenith_deg: float,
                generator: torch.Generator) -> torch.Tensor:
    """(count, 3) unit directions from one of :data:`LAYOUTS`, drawn by weight."""
    names = [name for name in LAYOUTS if weights.get(name, 0) > 0]
    p = torch.tensor([weights[name] for name in names], dtype=torch.float64)
    name = names[0] if len(names) == 1 else \
        names[int(torch.multinomial(p / p.sum(), 1, generator=generator))]   # one: no draw
    layout = {"cap": cap_lights, "dome": dome_lights, "ring": ring_lights, "panel": panel_lights}[name]
    return layout(count, max_zenith_deg, generator)


@dataclass(frozen=True)
class Camera:
    """How the simulated camera records a stack.

    Args:
        exposure: range of log10 of the level (full scale 1) that the stack's 99th percentile
            reaches; (−2, 0) spans two decades, from dim captures to a full-scale one.
        read_noise: largest standard deviation of the additive noise, in full-scale units.
        shot_noise: largest photon-noise factor g: the variance adds g · value.
        formats: weights of the storage formats in :data:`FORMATS`.
    """

    exposure: tuple[float, float] = (-2.0, 0.0)
    read_noise: float = 0.002
    shot_noise: float = 0.002
    formats: dict[str, float] = field(default_factory=lambda: {
        "float": 1.0, "round8": 1.0, "floor8": 1.0, "round16": 1.0})


def quantize(values: torch.Tensor, storage: str) -> torch.Tensor:
    """Values in [0, 1] full scale as unps reads them back from a file of that format.

    ``round8`` and ``round16`` round to 255 or 65535 levels (read as ``quantization=round``);
    ``floor8`` truncates a 16-bit value to its top 8 bits, as DiLiGenT's crops were made, and
    reads level k > 0 as k + ½ (``quantization=floor``, :func:`unps.io.images.read_image`);
    ``float`` keeps them.
    """
    if storage == "float":
        return values
    if storage == "round8":
        return torch.round(values * 255) / 255
    if storage == "round16":
        return torch.round(values * 65535) / 65535
    if storage == "floor8":
        levels = torch.floor(torch.round(values * 65535) / 256)
        return (levels + 0.5 * (levels > 0)) / 255
    raise ValueError(f"storage must be one of {FORMATS}, got {storage!r}")


@dataclass(frozen=True)
class Exposure:
    """The camera's random draws for one stack, made before it is recorded (so on the CPU, whatever
    device records it).

    Attributes:
        gain: the factor that brings the stack's 99th percentile to its level.
        shot, read: this stack's photon-noise factor and read-noise σ.
        noise: (n, 3, H, W) standard normal draws, or the seed of a generator that draws them on
            the device that records the stack (:func:`stack_noise`).
        storage: one of :data:`FORMATS`.
    """

    gain: float
    shot: float
    read: float
    noise: torch.Tensor | int
    storage: str


def expose(camera: Camera, shape: tuple[int, ...], generator: torch.Generator,
           defer_noise: bool = False) -> Exposure:
    """Draw the camera's settings and noise for a stack of ``shape`` (n, 3, H, W).

    ``defer_noise`` draws a seed in place of the noise, which the device recording the stack then
    draws itself: on a GPU, microseconds against half a sample's drawing time on a CPU core, and
    no 6 MB per sample (``recipe=paper``) to send there. The other draws stay those of the plain call but the
    storage format (drawn last, after the noise or the seed).
    """
    u = lambda *size: torch.rand(*size, generator=generator)    # noqa: E731
    low, high = camera.exposure
    gain = 10 ** (low + (high - low) * float(u(1)))
    shot, read = camera.shot_noise * float(u(1)), camera.read_noise * float(u(1))
    noise = (int(torch.randint(2 ** 62, (1,), generator=generator)) if defer_noise else
             torch.randn(shape, generator=generator))
    names = [name for name in FORMATS if camera.formats.get(name, 0) > 0]
    p = torch.tensor([camera.formats[name] for name in names], dtype=torch.float64)
    storage = names[int(torch.multinomial(p / p.sum(), 1, generator=generator))]
    return Exposure(gain, shot, read, noise, storage)


@dataclass(frozen=True)
class Exposures:
    """B stacks' camera draws (:class:`Exposure`) packed as a few tensors, so that a worker hands
    them over with its batch and the device recording them makes none of its own.

    Attributes:
        gain, shot, read_variance: (B,) float32: each stack's gain, photon-noise factor and read
            noise σ².
        noise: each stack's (n, 3, H, W) standard normal draws or its seed (:func:`stack_noise`).
        picks: one (k,) int64 tensor per entry of :data:`FORMATS`: the stacks stored in it.
    """

    gain: torch.Tensor
    shot: torch.Tensor
    read_variance: torch.Tensor
    noise: tuple[torch.Tensor | int, ...]
    picks: tuple[torch.Tensor, ...]

    @classmethod
    def of(cls, exposures: list[Exposure]) -> Exposures:
        """The draws of ``exposures``, packed."""
        values = lambda numbers: torch.tensor(numbers, dtype=torch.float32)   # noqa: E731
        return cls(values([e.gain for e in exposures]), values([e.shot for e in exposures]),
                   values([e.read ** 2 for e in exposures]), tuple(e.noise for e in exposures),
                   tuple(torch.tensor([i for i, e in enumerate(exposures) if e.storage == storage],
                                      dtype=torch.int64) for storage in FORMATS))


def record(images: torch.Tensor, exposure: Exposure) -> torch.Tensor:
    """One (n, 3, H, W) stack as the camera stores it (:func:`record_batch` of one)."""
    return record_batch(images[None], Exposures.of([exposure]))[0]


def stack_noise(noise: tuple[torch.Tensor | int, ...], shape: torch.Size,
                device: torch.device) -> torch.Tensor:
    """(B, *shape) standard normal draws on ``device``: each stack's draws moved there, or drawn
    there from a generator seeded with its seed (the same numbers on every run of one kind of
    device; a CPU and a GPU draw different ones). One generator is seeded anew for each such
    stack, which draws what a fresh one would."""
    generator, stacks = None, []
    for draws in noise:
        if isinstance(draws, torch.Tensor):
            stacks.append(to_device(draws, device))
            continue
        generator = generator or torch.Generator(device)
        stacks.append(torch.randn(shape, generator=generator.manual_seed(draws), device=device))
    return torch.stack(stacks)


def record_batch(images: torch.Tensor, exposures: Exposures) -> torch.Tensor:
    """Stacks scaled to a 99th percentile of 1, as the camera stores them.

    Args:
        images: (B, n, 3, H, W) radiance, each stack's 99th percentile of the object's values 1,
            on any device.
        exposures: the camera's draws for each stack, packed (:class:`Exposures`); their noise is
            moved to, or drawn on, the images' device.

    Returns:
        (B, n, 3, H, W) in [0, 1]: exposed, noisy, clipped at full scale and quantised.
    """
    device, shape = images.device, images.shape[1:]
    per_stack = lambda values: to_device(values, device).view(-1, 1, 1, 1, 1)   # noqa: E731
    values = images * per_stack(exposures.gain)
    sigma = torch.sqrt(per_stack(exposures.shot) * values.clamp_min(0) + per_stack(exposures.read_variance))
    values = (values + sigma * stack_noise(exposures.noise, shape, device)).clamp(0, 1)
    for storage, pick in zip(FORMATS, exposures.picks):
        if storage != "float" and len(pick):
            pick = to_device(pick, device)
            values[pick] = quantize(values[pick], storage)
    return values

"""The light benchmark's objects, rendered as captures unps has never seen.

Each object is a shape (a mesh of ``../shared/data/meshes`` in a random pose, or a procedural
shape with cavities, thin parts or self-shadowing), painted in patches of two or three MERL
materials (their neural fits in ``../shared/data/merl_nbrdf``; only the held-out half,
:data:`unps.lightnet.materials.HELD_OUT_MERL`, which the light network's training mix never
draws), lit by three rigs (a DiLiGenT-like dome of 96 lights, and sparse sets of 20 and 12
lights) and recorded by a camera with its own exposure, shot and read noise, saturation and
storage (8-bit rounded, 8-bit truncated from 16 bits as DiLiGenT's crops were made, 16-bit).

How an image is made (one per light i, directional, RGB intensity e_i):

- Mitsuba 3 traces the geometry: ground-truth normals, depth and each pixel's coverage c; and,
  for each light, the object rendered with a uniform diffuse stand-in material of albedo
  :data:`STAND_IN` once with direct light only (D_i) and once with up to :data:`BOUNCES` bounces
  (F_i), with the same samples. D_i / (a·c·max(n·l_i, 0)) is the share of each pixel the light
  reaches (cast shadows, antialiased), and F_i − D_i the interreflected light.
- The direct light is the MERL material's own reflectance, e_i·π·f(l_i, v)·max(n·l_i, 0) times
  that share and c, with f from the neural fit of the pixel's material and a smooth albedo texture.
- The interreflected light is F_i − D_i rescaled from the stand-in's albedo to the receiving
  pixel's (the material's directional-hemispherical albedo, in units where the matte white
  standard of :data:`WHITE` has its real albedo) and the object's mean: a diffuse approximation
  of the interreflections of glossy materials, close for matte ones.
- The outline (:data:`OUTLINES`): ``exact`` renders the pixels the object covers whole and
  nothing else, the mask exactly those; ``partial`` also renders the pixels it covers in part, as
  the covered share's light on a black background, and the mask holds the pixels covered at
  least :data:`DRAWN_AT`, as someone drawing a capture's mask would draw it.

Frame: x right, y up, z toward the camera (orthographic, looking down −z at [−1, 1]²).
"""

from __future__ import annotations

import hashlib
import json
import math
import tempfile
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
import scipy.io
import torch
import trimesh
from scipy.ndimage import gaussian_filter, zoom

from unps.data.diligent import find_diligent_object
from unps.data.layout import DIRECTIONS, FILENAMES, INTENSITIES, MASK, NORMALS
from unps.io.files import atomic_dir, atomic_path
from unps.io.images import write_png8, write_png16
from unps.lightnet.brdf import read_neural_brdf
from unps.lightnet.materials import HELD_OUT_MERL
from unps.lightnet.rig import cap_lights, dome_lights, ring_lights
from unps.synthetic import shapes, vessels
from unps.synthetic.render import (_scene, _traced, _write_mesh, covered_whole, procedural_albedo,
                                   set_variant)

RESOLUTION = 128         # the captures' side in pixels, unless an object asks for another
SPP = 16                 # a square: the stratified sampler's grid
BOUNCES = 4              # the path tracer's longest path for the interreflections
STAND_IN = 0.5           # albedo of the diffuse stand-in material
WHITE = ("white-diffuse-bball", 0.85)   # a matte white standard and the albedo it has: the neural
                         # fits' units make it 0.28, so every material's albedo is scaled alike
LIGHT_SETS = {"96": 96, "20": 20, "12": 12}
FORMATS = ("floor8", "round8", "png16")
OUTLINES = ("exact", "partial")
DRAWN_AT = 0.5           # a partial outline's mask: the pixels the object covers at least half of
SCENE_VERSION = 1        # bump when a change here alters the rendered radiance
CAMERA_VERSION = 2       # bump when a change to the camera alters the captures


@dataclass(frozen=True)
class BenchmarkObject:
    """One object of the benchmark.

    Attributes:
        name: its name.
        shape: a builder in :data:`SHAPES` and its arguments.
        materials: two or three held-out MERL materials, laid on in patches (one in
            :data:`SINGLE_MATERIAL`).
        storage: one of :data:`FORMATS`.
        seed: draws the pose, patches, texture, lights and camera.
        rig: ``drawn`` (:func:`draw_rig`) or ``diligent``: DiLiGenT's own 96 lights, directions and
            intensities as ball's files give them (:func:`diligent_rig`).
        bounces: the path tracer's longest path for the interreflections (:data:`BOUNCES`); 2
            renders the direct light alone, cast shadows included and no interreflection.
        outline: one of :data:`OUTLINES` (module docstring).
        resolution: the captures' side in pixels. The materials' patches and the texture are
            drawn at :data:`RESOLUTION` and stretched to it, so that only the pixels change.
    """

    name: str
    shape: tuple[str, dict]
    materials: tuple[str, ...]
    storage: str
    seed: int
    rig: str = "drawn"
    bounces: int = BOUNCES
    outline: str = "exact"
    resolution: int = RESOLUTION

    def key(self, camera: bool = True) -> str:
        """A short hash of everything that makes its radiance (and, with ``camera``, its captures);
        the drawn rig and the exact outline, the first of each, add nothing to it."""
        spec = {**asdict(self), "version": SCENE_VERSION, "spp": SPP}
        if self.rig == "drawn":
            del spec["rig"]
        if self.outline == "exact":               # the captures rendered before it was an option
            del spec["outline"]
        if camera:
            spec["camera"] = CAMERA_VERSION
        return hashlib.sha256(json.dumps(spec, sort_keys=True).encode()).hexdigest()[:10]


# shapes of the benchmark alone ------------------------------------------------------------

def torus_knot(p: int = 2, q: int = 3, tube: float = 0.12, segments: int = 400, sides: int = 24,
               seed: int = 0) -> shapes.Mesh:
    """A (p, q) torus knot: a thin tube passing over and under itself."""
    t = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    r = 0.6 + 0.25 * np.cos(q * t)
    centre = np.stack([r * np.cos(p * t), r * np.sin(p * t), 0.25 * np.sin(q * t)], 1)
    tangent = np.roll(centre, -1, 0) - np.roll(centre, 1, 0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    side = np.cross(tangent, [0.0, 0.0, 1.0])
    side /= np.linalg.norm(side, axis=1, keepdims=True)
    up = np.cross(side, tangent)
    angle = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    ring = np.cos(angle)[None, :, None] * side[:, None] + np.sin(angle)[None, :, None] * up[:, None]
    mesh = shapes.parametric_mesh(centre[:, None] + tube * ring, wrap=True)
    faces = mesh.faces.copy()
    index = np.arange(segments * sides).reshape(segments, sides)       # close the tube's loop
    last, first = index[-1], index[0]
    a, b, c, d = last, np.roll(last, -1), np.roll(first, -1), first
    faces = np.concatenate([faces, np.stack([a, d, c], 1), np.stack([a, c, b], 1)])
    return _posed(shapes.Mesh(mesh.vertices, faces.astype(np.int32)), seed)


def torus(radius: float = 0.65, tube: float = 0.22, seed: int = 0) -> shapes.Mesh:
    """A ring: its hole shows what lies behind, its inner side shades itself."""
    m = trimesh.creation.torus(major_radius=radius, minor_radius=tube, major_sections=96,
                               minor_sections=40)
    return _posed(shapes.Mesh(np.asarray(m.vertices, np.float32), np.asarray(m.faces, np.int32)), seed)


def spheres(count: int = 6, seed: int = 0) -> shapes.Mesh:
    """Overlapping spheres of several sizes: each casts shadows on its neighbours."""
    rng = np.random.default_rng(seed)
    parts = []
    for _ in range(count):
        m = trimesh.creation.icosphere(subdivisions=4, radius=rng.uniform(0.25, 0.5))
        parts.append(shapes.Mesh(np.asarray(m.vertices + rng.uniform(-0.5, 0.5, 3), np.float32),
                                 np.asarray(m.faces, np.int32)))
    return shapes.fit_to_view(shapes.merge(*parts))


def pits(resolution: int = 256, seed: int = 0) -> shapes.Mesh:
    """A plaque with deep round pits and tall pillars: steep walls and long cast shadows."""
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(np.linspace(-1, 1, resolution), np.linspace(1, -1, resolution))
    z = 0.1 * np.exp(-(x ** 2 + y ** 2))
    for _ in range(14):
        cx, cy, radius = rng.uniform(-0.7, 0.7), rng.uniform(-0.7, 0.7), rng.uniform(0.06, 0.16)
        height = rng.choice([-1, 1]) * rng.uniform(0.15, 0.35)
        z += height / (1 + np.exp((np.hypot(x - cx, y - cy) - radius) / 0.012))
    inside = (np.abs(x) < 0.9) & (np.abs(y) < 0.9)
    tilt = np.radians(rng.uniform(-25, 25, 2))
    return shapes.height_field_mesh(z + x * np.tan(tilt[0]) + y * np.tan(tilt[1]), inside)


def mesh_file(name: str, seed: int = 0, data: str = "") -> shapes.Mesh:
    """A mesh of ``<data>/meshes`` in a random pose (seeded)."""
    loaded = trimesh.load(Path(data) / "meshes" / name, force="mesh", process=False)
    vertices = np.asarray(loaded.vertices, np.float64)
    return _posed(shapes.Mesh((vertices - vertices.mean(0)).astype(np.float32),
                              np.asarray(loaded.faces, np.int32)), seed)


def _posed(mesh: shapes.Mesh, seed: int) -> shapes.Mesh:
    rotation = trimesh.transformations.random_rotation_matrix(
        rand=np.random.default_rng(seed).random(3))[:3, :3]
    return shapes.fit_to_view(shapes.Mesh((mesh.vertices @ rotation.T).astype(np.float32),
                                          mesh.faces), extent=0.9)


SHAPES = {"mesh": mesh_file, "vase": vessels.vase, "goblet": vessels.goblet, "bowl": vessels.bowl,
          "broken_pot": shapes.broken_pot, "rose": shapes.rose, "face": shapes.face,
          "tablet": shapes.tablet, "golf_ball": shapes.golf_ball, "torus_knot": torus_knot,
          "torus": torus, "spheres": spheres, "pits": pits}


def _objects() -> tuple[BenchmarkObject, ...]:
    m = HELD_OUT_MERL
    spec = [  # name, (builder, arguments), materials
        ("blob01", ("mesh", {"name": "blob01.obj", "seed": 1}),
         ("white-diffuse-bball", "red-specular-plastic")),
        ("blob02", ("mesh", {"name": "blob02.obj", "seed": 2}), ("steel", "black-soft-plastic")),
        ("blob03", ("mesh", {"name": "blob03.obj", "seed": 3}), ("specular-black-phenolic", "white-paint")),
        ("blob04", ("mesh", {"name": "blob04.obj", "seed": 4}), ("alumina-oxide", "specular-green-phenolic")),
        ("blob07", ("mesh", {"name": "blob07.obj", "seed": 5}), ("nickel", "pvc", "yellow-paint")),
        ("blob08", ("mesh", {"name": "blob08.obj", "seed": 6}), ("yellow-plastic", "pink-jasper")),
        ("blob09", ("mesh", {"name": "blob09.obj", "seed": 7}), ("grease-covered-steel", "white-fabric2")),
        ("bunny", ("mesh", {"name": "bunny_res2.ply", "seed": 8}), ("white-diffuse-bball", "brass")),
        ("bunny-dark", ("mesh", {"name": "bunny_res2.ply", "seed": 9}),
         ("black-oxidized-steel", "specular-orange-phenolic")),
        ("vase-a", ("vase", {"tilt_deg": 35, "seed": 3, "turn_deg": 20}),
         ("specular-yellow-phenolic", "white-paint")),
        ("vase-b", ("vase", {"tilt_deg": 65, "seed": 5, "turn_deg": -30}),
         ("tungsten-carbide", "dark-blue-paint")),
        ("goblet-a", ("goblet", {"tilt_deg": 15, "turn_deg": 5}),
         ("silver-paint", "specular-black-phenolic")),
        ("goblet-b", ("goblet", {"tilt_deg": 45, "turn_deg": 40}),
         ("specular-violet-phenolic", "alumina-oxide")),
        ("bowl-a", ("bowl", {"tilt_deg": 35, "turn_deg": 0}), ("white-paint", "red-phenolic")),
        ("bowl-b", ("bowl", {"tilt_deg": 60, "turn_deg": 110}),
         ("polyethylene", "gold-paint", "natural-209")),
        ("pot-shard", ("broken_pot", {"seed": 4}), ("pink-fabric2", "yellow-paint")),
        ("rose", ("rose", {"seed": 2}), ("violet-rubber", "light-red-paint")),
        ("face", ("face", {"seed": 3}), ("natural-209", "pure-rubber")),
        ("tablet", ("tablet", {"seed": 5}), ("fruitwood-241", "silver-metallic-paint")),
        ("golf-ball", ("golf_ball", {"seed": 7}), ("white-diffuse-bball", "specular-black-phenolic")),
        ("knot", ("torus_knot", {"seed": 3}), ("two-layer-silver", "green-fabric")),
        ("spheres", ("spheres", {"seed": 4}),
         ("blue-metallic-paint2", "white-diffuse-bball", "orange-paint")),
        ("ring", ("torus", {"seed": 11}), ("red-fabric2", "color-changing-paint2")),
        ("pits", ("pits", {"seed": 6}), ("colonial-maple-223", "black-fabric")),
    ]
    out = []
    for k, (name, shape, materials) in enumerate(spec):
        assert all(material in m for material in materials), materials
        out.append(BenchmarkObject(name, shape, materials, FORMATS[k % 3], seed=1000 + k))
    return tuple(out)


OBJECTS = _objects()

SINGLE_MATERIAL = tuple(replace(obj, materials=obj.materials[:1]) for obj in OBJECTS)
"""The same 24 objects, each in the first of its materials alone: the same shape, pose, texture,
lights, camera and storage (the same seed), so that a network's error on an object of one
material is read beside its error on the object painted in patches. DiLiGenT's objects are
mostly of one material, and so are many users' captures."""

ON_DILIGENT_RIG = tuple(replace(obj, rig="diligent") for obj in OBJECTS)
"""The same 24 objects (shape, pose, materials, camera, storage) lit by DiLiGenT's own dome
(:func:`diligent_rig`) rather than a rig drawn as the light network's training draws them: the
lights of a real rig, which the training's layouts did not make."""


# rendering --------------------------------------------------------------------------------

@dataclass
class Rig:
    """One object's lights: (n, 3) unit directions (surface to light) and (n, 3) RGB intensities
    for each light set of :data:`LIGHT_SETS`."""

    directions: dict[str, np.ndarray] = field(default_factory=dict)
    intensities: dict[str, np.ndarray] = field(default_factory=dict)


def draw_rig(seed: int) -> Rig:
    """A DiLiGenT-like dome of 96 lights within 50° of the view, and sparse sets of 20 and 12
    lights as a cap, rings or a grid within 60° (one layout each, drawn)."""
    generator = torch.Generator().manual_seed(seed)
    rng = np.random.default_rng(seed)
    rig = Rig()
    for label, count in LIGHT_SETS.items():
        if count == 96:
            directions = dome_lights(count, 50.0, generator)
        else:
            layout = (cap_lights, ring_lights, dome_lights)[int(rng.integers(3))]
            directions = layout(count, 60.0, generator)
        rig.directions[label] = directions.numpy().astype(np.float64)
        brightness = rng.uniform(0.6, 1.4, (count, 1))
        rig.intensities[label] = brightness * rng.uniform(0.95, 1.05, (count, 3))
    return rig


def diligent_rig(data: Path) -> Rig:
    """DiLiGenT's dome as ball's files give it (``<data>/DiLiGenT``): its 96 light directions and
    RGB intensities, and the sets of 20 and 12 evenly spread over them (:func:`evenly_spread`),
    as the light benchmark takes DiLiGenT's objects.

    Raises:
        InputError: DiLiGenT's ball is not under ``data``.
    """
    folder = find_diligent_object(data / "DiLiGenT", "ball")
    directions = np.loadtxt(folder / DIRECTIONS, dtype=np.float64)
    intensities = np.loadtxt(folder / INTENSITIES, dtype=np.float64)
    rig = Rig()
    for label, count in LIGHT_SETS.items():
        chosen = evenly_spread(directions, count)
        rig.directions[label], rig.intensities[label] = directions[chosen], intensities[chosen]
    return rig


def evenly_spread(directions: np.ndarray, count: int) -> np.ndarray:
    """Indices of ``count`` of the (n, 3) unit directions, spread evenly: the one nearest the
    view axis (+z), then each time the one farthest from those chosen (sorted).

    >>> evenly_spread(np.array([[0, 0, 1.0], [0.1, 0, 0.995], [0.6, 0, 0.8], [-0.6, 0, 0.8]]), 3)
    array([0, 2, 3])
    """
    chosen = [int(np.argmax(directions[:, 2]))]
    nearest = directions @ directions[chosen[0]]
    while len(chosen) < min(count, len(directions)):
        chosen.append(int(np.argmin(nearest)))
        nearest = np.maximum(nearest, directions @ directions[chosen[-1]])
    return np.sort(chosen)


def hemispherical_albedo(brdf, samples: int = 4096, seed: int = 0) -> np.ndarray:
    """(3,) ∫ f(l, v) cos θ_l dl over the hemisphere, averaged over views at 0°, 30° and 60°."""
    generator = torch.Generator().manual_seed(seed)
    u = torch.rand(samples, 2, generator=generator)
    z = torch.sqrt(1 - u[:, 0])                     # cosine-weighted: pdf cos θ / π
    r = torch.sqrt(u[:, 0])
    wi = torch.stack([r * torch.cos(2 * math.pi * u[:, 1]), r * torch.sin(2 * math.pi * u[:, 1]), z], -1)
    values = []
    for view in (0.0, 30.0, 60.0):
        t = math.radians(view)
        wo = torch.tensor([math.sin(t), 0.0, math.cos(t)]).expand_as(wi)
        values.append(math.pi * brdf(wi, wo).mean(0))
    return torch.stack(values).mean(0).numpy()


def material_map(mask: np.ndarray, count: int, seed: int) -> np.ndarray:
    """(H, W) material index in [0, count): patches with sharp edges from a smooth random field
    (drawn at :data:`RESOLUTION`, stretched to H = W) cut at its quantiles over the object, so
    that each material covers a similar share."""
    rng = np.random.default_rng(seed)
    field_ = gaussian_filter(rng.standard_normal((RESOLUTION, RESOLUTION)),
                             RESOLUTION * rng.uniform(0.06, 0.14))
    field_ = stretched(field_, mask.shape[0])
    cuts = np.quantile(field_[mask], np.arange(1, count) / count)
    return np.searchsorted(cuts, field_).astype(np.int64)


def stretched(values: np.ndarray, side: int) -> np.ndarray:
    """(S, S, ...) ``values`` resampled (bilinear) to (side, side, ...); themselves at S = side."""
    if values.shape[0] == side:
        return values
    factor = side / values.shape[0]
    return zoom(values, (factor, factor) + (1,) * (values.ndim - 2), order=1, grid_mode=True,
                mode="nearest")


def direct_light(normals: np.ndarray, brdf, directions: np.ndarray) -> np.ndarray:
    """(n, m, 3) π·f(l_i, v)·max(n·l_i, 0) at m pixels of (m, 3) unit ``normals``, view +z."""
    n = torch.as_tensor(normals, dtype=torch.float32)
    helper = torch.where(n[:, :1].abs() < 0.9, torch.tensor([1.0, 0, 0]), torch.tensor([0, 1.0, 0]))
    tangent = torch.nn.functional.normalize(torch.linalg.cross(helper, n), dim=-1)
    frame = torch.stack([tangent, torch.linalg.cross(n, tangent), n], 1)          # (m, 3, 3) rows
    wi = torch.einsum("mij,lj->lmi", frame, torch.as_tensor(directions, dtype=torch.float32))
    wo = frame[:, :, 2][None].expand_as(wi)
    with torch.no_grad():
        return (math.pi * brdf(wi, wo) * wi[..., 2:].clamp_min(0)).numpy()


def render_radiance(obj: BenchmarkObject, data: Path, rig: Rig, progress=None):
    """Radiance of every light of every set, with the ground truth.

    Returns:
        {label: (n, H, W, 3) float32 radiance}, normals (H, W, 3), depth (H, W), mask (H, W): the
        truth on the mask, as ``obj.outline`` draws it.
    """
    import mitsuba as mi

    builder, arguments = obj.shape
    extra = {"data": str(data)} if builder == "mesh" else {}
    mesh = SHAPES[builder](**arguments, **extra)
    set_variant("scalar_rgb")
    with tempfile.TemporaryDirectory() as tmp:
        path = _write_mesh(mesh, Path(tmp))
        normals, depth, coverage = _traced(path, obj.resolution, obj.seed)
        whole = covered_whole(coverage, depth)
        shown, mask, share = outline(whole, coverage, np.isfinite(depth), obj.outline)
        stand_in = {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": STAND_IN}}
        scenes = {bounces: _scene(path, stand_in, {"type": "path", "max_depth": bounces},
                                  obj.resolution, SPP, "stratified") for bounces in {2, obj.bounces}}
        params = {bounces: mi.traverse(scene) for bounces, scene in scenes.items()}
        brdfs = [read_neural_brdf(data / "merl_nbrdf" / f"{name}.h5") for name in obj.materials]
        white = hemispherical_albedo(read_neural_brdf(data / "merl_nbrdf" / f"{WHITE[0]}.h5")).mean()
        units = WHITE[1] / white
        albedos = np.stack([hemispherical_albedo(b) for b in brdfs]) * units         # (k, 3)
        which = material_map(whole, len(brdfs), obj.seed)[shown]
        texture = stretched(procedural_albedo(obj.seed, RESOLUTION, feature=0.05, contrast=0.15),
                            obj.resolution)[shown]
        receiving = np.minimum(albedos[which] * texture, 0.95)                   # (m, 3)
        mean_albedo = receiving.mean(0)
        out = {}
        for label, directions in rig.directions.items():
            direct = np.zeros((len(directions), int(shown.sum()), 3), np.float32)
            for k, brdf in enumerate(brdfs):
                direct[:, which == k] = direct_light(normals[shown][which == k], brdf, directions)
            direct *= texture[None] * units
            shading = np.clip(normals[shown] @ directions.T, 0, None).T             # (n, m)
            images = np.zeros((len(directions), *shown.shape, 3), np.float32)
            for i, light in enumerate(directions):
                seed = obj.seed * 7919 + i
                only_direct = _render(scenes[2], params[2], light, seed)
                full = (_render(scenes[obj.bounces], params[obj.bounces], light, seed)
                        if obj.bounces > 2 else only_direct)
                lit = np.where(shading[i] > 0.02, only_direct[shown].mean(-1)
                               / (STAND_IN * np.maximum(shading[i], 0.02) * share), 1.0).clip(0, 1)
                bounced = np.clip(full - only_direct, 0, None)[shown] * (receiving / STAND_IN) \
                    * (mean_albedo / STAND_IN)
                images[i][shown] = direct[i] * (lit * share)[:, None] + bounced
                if progress:
                    progress()
            out[label] = images * rig.intensities[label][:, None, None, :].astype(np.float32)
    normals = np.where(mask[..., None], normals, 0)
    return out, normals, np.where(mask, depth, np.nan), mask


def outline(whole: np.ndarray, coverage: np.ndarray, finite: np.ndarray, kind: str
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Which pixels an outline of ``kind`` (:data:`OUTLINES`) renders and masks.

    Args:
        whole: (H, W) bool, the pixels the object covers whole.
        coverage: (H, W) the share of each pixel the object covers.
        finite: (H, W) bool, the pixels with a finite normal and depth.

    Returns:
        shown (H, W) bool, the pixels rendered; mask (H, W) bool, the capture's mask; share (m,)
        the coverage of the m shown pixels (1 on the whole ones).

    >>> coverage = np.array([[0.0, 0.3, 0.7, 1.0]])
    >>> shown, mask, share = outline(coverage == 1, coverage, coverage >= 0, "partial")
    >>> shown.astype(int).tolist(), mask.astype(int).tolist(), share.tolist()
    ([[0, 1, 1, 1]], [[0, 0, 1, 1]], [0.3, 0.7, 1.0])
    """
    if kind == "exact":
        return whole, whole, np.ones(int(whole.sum()))
    if kind != "partial":
        raise ValueError(f"outline must be one of {OUTLINES}, got {kind!r}")
    shown = (coverage > 0) & finite
    share = np.where(whole, 1.0, coverage)[shown]
    return shown, shown & (coverage >= DRAWN_AT), share


def _render(scene, params, light: np.ndarray, seed: int) -> np.ndarray:
    import mitsuba as mi

    up = [0, 1, 0] if abs(light[1]) < 0.9 else [1, 0, 0]
    params["light.to_world"] = mi.ScalarAffineTransform4f().look_at(origin=[0, 0, 0],
                                                                     target=list(-light), up=up)
    params["light.irradiance.value"] = mi.ScalarColor3f(math.pi, math.pi, math.pi)
    params.update()
    return np.array(mi.render(scene, seed=seed))[..., :3]


# the camera -------------------------------------------------------------------------------

def record(radiance: dict[str, np.ndarray], mask: np.ndarray, obj: BenchmarkObject
           ) -> dict[str, np.ndarray]:
    """Each light set exposed so that the object's 99th percentile over the 96-light set reaches
    a level between 0.1 and 0.9 of full scale (log-uniform; dark captures lose range as pot1's
    crops do), with photon noise (variance g·value, g between 10⁻⁵ and 2·10⁻⁴ of full scale: a
    sensor's full well of 5,000 to 100,000 electrons) and read noise (σ between 2·10⁻⁴ and
    10⁻³), clipped at full scale (highlights saturate).

    Returns:
        {label: (n, H, W, 3) values in [0, 1], before storage}.
    """
    rng = np.random.default_rng(obj.seed + 1)
    level = 0.1 * 9 ** rng.uniform()
    scale = level / np.percentile(radiance["96"][:, mask], 99)
    shot, read = 1e-5 * 20 ** rng.uniform(), rng.uniform(2e-4, 1e-3)
    out = {}
    for label, images in radiance.items():
        values = images * scale
        sigma = np.sqrt(shot * values + read ** 2)
        out[label] = np.clip(values + sigma * rng.standard_normal(values.shape), 0, 1).astype(np.float32)
    return out


def stored(values: np.ndarray, storage: str) -> np.ndarray:
    """Integer levels as the file stores them: uint8 rounded, uint8 truncated from 16 bits, or
    uint16 rounded."""
    if storage == "round8":
        return np.round(values * 255).astype(np.uint8)
    if storage == "floor8":
        return (np.round(values * 65535).astype(np.uint16) // 256).astype(np.uint8)
    if storage == "png16":
        return np.round(values * 65535).astype(np.uint16)
    raise ValueError(f"storage must be one of {FORMATS}, got {storage!r}")


def quantization(storage: str) -> str:
    """How unps must read a capture stored this way (``subject.quantization``)."""
    return "floor" if storage == "floor8" else "round"


def write_capture(folder: Path, values: np.ndarray, storage: str, directions: np.ndarray,
                  intensities: np.ndarray, mask: np.ndarray, normals: np.ndarray, meta: dict) -> None:
    """One capture in the DiLiGenT layout, atomically."""
    names = [f"{i + 1:03d}.png" for i in range(len(values))]
    with atomic_dir(folder, overwrite=True) as tmp:
        (tmp / FILENAMES).write_text("\n".join(names) + "\n")
        for name, image in zip(names, values):
            levels = stored(image, storage)
            if storage == "png16":
                write_png16(tmp / name, levels / 65535.0)
            else:
                write_png8(tmp / name, levels)
        np.savetxt(tmp / DIRECTIONS, directions, fmt="%.9g")
        np.savetxt(tmp / INTENSITIES, intensities, fmt="%.9g")
        write_png8(tmp / MASK, np.repeat(mask[..., None], 3, -1) * np.uint8(255))
        scipy.io.savemat(tmp / NORMALS, {"Normal_gt": normals})
        (tmp / "benchmark.json").write_text(json.dumps(meta, indent=2) + "\n")


def make_captures(obj: BenchmarkObject, data: Path, cache: Path, progress=None) -> dict[str, Path]:
    """The object's three captures (one folder per light set), recorded from its radiance, which
    is rendered unless cached.

    Returns:
        {label: folder}.
    """
    folders = {label: cache / f"{obj.name}-{obj.key()}" / label for label in LIGHT_SETS}
    if all((folder / "benchmark.json").is_file() for folder in folders.values()):
        return folders
    rig = diligent_rig(data) if obj.rig == "diligent" else draw_rig(obj.seed)
    stored_radiance = cache / "radiance" / f"{obj.name}-{obj.key(camera=False)}.npz"
    if stored_radiance.is_file():
        with np.load(stored_radiance) as f:
            radiance = {label: f[label].astype(np.float32) for label in LIGHT_SETS}
            normals, mask = f["normals"], f["mask"]
    else:
        radiance, normals, _, mask = render_radiance(obj, data, rig, progress)
        stored_radiance.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(stored_radiance) as tmp:
            with open(tmp, "wb") as f:
                np.savez_compressed(f, normals=normals, mask=mask, **radiance)
    values = record(radiance, mask, obj)
    for label, folder in folders.items():
        meta = {**asdict(obj), "light_set": label, "quantization": quantization(obj.storage),
                "key": obj.key()}
        write_capture(folder, values[label], obj.storage, rig.directions[label],
                      rig.intensities[label], mask, normals, meta)
    return folders

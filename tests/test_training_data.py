"""The light network's training data: shape families, light layouts and the simulated camera."""

import dataclasses
import math

import cv2
import numpy as np
import pytest
import torch
import torch.nn.functional as F
from hydra import compose, initialize_config_module
from omegaconf import OmegaConf
from torch.utils.data import DataLoader, default_collate

from unps.errors import InputError
from unps.io.images import read_image, write_png16
from unps.lightnet import lathe
from unps.lightnet.brdf import NeuralBRDF
from unps.lightnet.brdf import AnalyticBRDF
from unps.lightnet.materials import MaterialBank, coated, darkened
from unps.lightnet.rig import FORMATS, LAYOUTS, Camera, draw_lights, expose, quantize, record, stack_noise
from unps.lightnet.shapes import GROOVE_LENGTH, GROOVE_WIDTH, SHAPES, groove_depth, sample_generator
from unps.lightnet.data import Draws, LightData, loader_workers
from unps.lightnet.synthesis import (ROOM_LIGHT_MAX, LightDataset, SceneBatch, map_tensors, render,
                                     render_batch, with_room_light)


def concave_share(depth: torch.Tensor, mask: torch.Tensor) -> float:
    """Share of the mask's interior (2 px in from the outline) where the depth's Laplacian is > 0."""
    z = depth
    laplacian = (z[2:, 1:-1] + z[:-2, 1:-1] + z[1:-1, 2:] + z[1:-1, :-2] - 4 * z[1:-1, 1:-1])
    inner = (-F.max_pool2d(-mask[None, None].float(), 5, 1, 2)[0, 0] > 0.5)[1:-1, 1:-1]
    return float((laplacian[inner] > 0).float().mean())


@pytest.mark.parametrize("family", list(SHAPES))
def test_every_shape_family_renders_finite_unit_normals_on_a_mask(family):
    for index in range(4):
        maps = SHAPES[family](64, sample_generator(0, index))
        assert maps.mask.sum() > 64 * 64 * 0.05
        assert torch.isfinite(maps.normals).all() and torch.isfinite(maps.depth).all()
        torch.testing.assert_close(maps.normals[maps.mask].norm(dim=-1), torch.ones(int(maps.mask.sum())))
        assert (maps.normals[maps.mask][:, 2] > 0).all()          # seen from the camera
        assert not maps.normals[~maps.mask].any()


def test_vessels_are_concave_where_blobs_are_convex():
    for index in range(6):
        vessel = SHAPES["vessel"](64, sample_generator(0, index))
        blob = SHAPES["blob"](64, sample_generator(0, index))
        assert concave_share(vessel.depth, vessel.mask) > 0.15
        assert concave_share(blob.depth, blob.mask) < 0.05


def test_dishes_are_concave_and_their_outline_is_a_rim_that_faces_inward():
    """A dish seen from inside: mostly concave, and on its outline the normals lean toward the
    middle (a dome's lean outward), which is what makes it the dome's mirrored reading."""
    for index in range(6):
        dish = SHAPES["dish"](64, sample_generator(0, index))
        assert concave_share(dish.depth, dish.mask) > 0.6
        inner = -F.max_pool2d(-dish.mask[None, None].float(), 3, 1, 1)[0, 0] > 0.5
        rim = dish.mask & ~inner
        rows, cols = torch.nonzero(rim, as_tuple=True)
        outward = torch.stack([cols - cols.float().mean(), -(rows - rows.float().mean())], -1)
        lean = (dish.normals[rim][:, :2] * torch.nn.functional.normalize(outward, dim=-1)).sum(-1)
        assert lean.mean() < 0


def test_rasterising_keeps_the_nearest_point_and_its_normal():
    t = torch.linspace(-0.5, 0.5, 200)
    square = torch.stack(torch.meshgrid(t, t, indexing="ij"), -1).reshape(-1, 2)
    near = torch.cat([square, torch.full((len(square), 1), 0.3)], 1)
    far = torch.cat([square * 1.6, torch.full((len(square), 1), -0.2)], 1)
    tilted = F.normalize(torch.tensor([0.3, 0.0, 1.0]), dim=0)
    normals, depth, mask = lathe.rasterise(*torch.cat([far, near]).unbind(-1), torch.cat(
        [torch.tensor([0.0, 0, 1]).expand_as(far), tilted.expand_as(near)]), 64)
    centre, ring = (slice(24, 40),) * 2, (slice(8, 12), slice(28, 36))
    assert mask[centre].all() and mask[ring].all()
    torch.testing.assert_close(depth[centre], torch.full((16, 16), 0.3))
    torch.testing.assert_close(normals[centre], tilted.expand(16, 16, 3))
    torch.testing.assert_close(depth[ring], torch.full((4, 8), -0.2))
    assert not mask[:2].any()                                       # beyond both sheets


def test_a_sheet_shows_the_camera_whichever_side_faces_it():
    t = torch.linspace(-0.5, 0.5, 200)
    square = torch.stack(torch.meshgrid(t, t, indexing="ij"), -1).reshape(-1, 2)
    points = torch.cat([square, torch.zeros(len(square), 1)], 1)
    away = F.normalize(torch.tensor([0.3, 0.0, -1.0]), dim=0).expand_as(points)
    _, _, one_sided = lathe.rasterise(*points.unbind(-1), away, 64)
    normals, _, mask = lathe.rasterise(*points.unbind(-1), away, 64, two_sided=True)
    assert not one_sided.any()
    centre = (slice(24, 40),) * 2
    assert mask[centre].all()
    torch.testing.assert_close(normals[centre], (-away[0]).expand(16, 16, 3))


def test_a_jar_of_no_thickness_is_one_sheet_without_a_lip():
    def radius(h):
        return 0.4 + 0.1 * torch.cos(3 * h)

    jar = lathe.jar_points(radius, 1.2, 0.3, 0.0, samples=64)
    points, normals = jar.points, jar.normals()
    on_wall = points[:, 2] > 0
    height = points[on_wall, 2] / 1.2
    torch.testing.assert_close(points[on_wall, :2].norm(dim=-1), radius(height))   # no inner wall
    outward = (normals[on_wall, :2] * points[on_wall, :2]).sum(-1)
    assert (outward > 0).all()                                  # no lip ring, no inner floor
    thick = lathe.jar_points(radius, 1.2, 0.3, 0.03, samples=64).points
    assert len(thick) > 1.9 * len(points)


@pytest.mark.parametrize("wall", [0.0, 0.03])
def test_a_jar_seen_through_the_normals_it_shows_is_the_jar_seen_through_all_of_them(wall):
    """jar_view turns only the normals of the points that show: the maps of every point turned
    and rasterised, to the bit."""
    def radius(h):
        return 0.4 + 0.1 * torch.cos(3 * h)

    tilt, turn, extent, resolution = 0.9, 2.1, 1.5, 48
    maps = lathe.jar_view(radius, 1.2, 0.3, wall, tilt, turn, extent, resolution)
    jar = lathe.jar_points(radius, 1.2, 0.3, wall, samples=4 * resolution)
    c, s, ct, st = math.cos(tilt), math.sin(tilt), math.cos(turn), math.sin(turn)
    rotation = torch.tensor([[ct, -st, 0], [st, ct, 0], [0, 0, 1.0]]) @ torch.tensor(
        [[1.0, 0, 0], [0, c, -s], [0, s, c]])
    # turned as jar_view turns them, each coordinate's products summed in order: a (p, 3) × (3, 3)
    # matmul may fuse them (an Intel Xeon's kernels do; an AMD EPYC's did not), which is not the point
    points, normals = (torch.stack([lathe._rotated(v.unbind(-1), row) for row in rotation], -1)
                       for v in (jar.points, jar.normals()))
    low, high = points.min(0).values, points.max(0).values
    points = (points - (low + high) / 2) * (extent / float((high - low)[:2].max()))
    whole = lathe.rasterise(*points.unbind(-1), normals, resolution, two_sided=wall == 0)
    assert all(torch.equal(a, b) for a, b in zip(maps, whole))


def test_grooves_worked_out_around_each_groove_are_those_worked_out_over_the_whole_image():
    g = torch.Generator().manual_seed(5)
    for resolution in (32, 64, 128, 256):
        count = 150
        u = lambda *shape: torch.rand(*shape, generator=g)           # noqa: E731
        start, turn = (u(count, 2, 1, 1) - 0.5) * 1.6, math.pi * u(count, 1, 1)
        length = GROOVE_LENGTH[0] + GROOVE_LENGTH[1] * u(count, 1, 1)
        width = GROOVE_WIDTH[0] + GROOVE_WIDTH[1] * u(count, 1, 1)
        length[:3], width[:3] = sum(GROOVE_LENGTH), sum(GROOVE_WIDTH)     # the longest and widest
        depth = 0.008 + 0.025 * u(count, 1, 1)
        t = torch.linspace(-1, 1, resolution)
        x, y = t[None, :].expand(resolution, resolution), -t[:, None].expand(resolution, resolution)
        px, py = x - start[:, 0], y - start[:, 1]
        cos, sin = torch.cos(turn), torch.sin(turn)
        along = torch.minimum((px * cos + py * sin).clamp_min(0), length)
        distance = torch.hypot(px - along * cos, py - along * sin)
        whole = (depth * (1 - distance / width).clamp_min(0)).sum(0)
        assert whole.count_nonzero() > 0.05 * resolution ** 2
        assert torch.equal(groove_depth(resolution, start, turn, length, width, depth), whole)


def test_jars_show_their_inside_past_the_near_lip():
    shown_inside = 0
    for index in range(6):
        maps = SHAPES["jar"](64, sample_generator(0, index))
        rows, cols = torch.gradient(maps.depth)
        inner = (-F.max_pool2d(-maps.mask[None, None].float(), 3, 1, 1)[0, 0] > 0.5)
        shown_inside += bool((torch.hypot(rows, cols)[inner] > 0.25).any())   # a step at the lip (other families: < 0.16)
    assert shown_inside >= 5


def interior_tilt(family: str, index: int) -> float:
    """90th percentile of the angle (degrees) between a shape's normals 4 px inside its outline
    and their mean direction."""
    maps = SHAPES[family](64, sample_generator(0, index))
    inner = -F.max_pool2d(-maps.mask[None, None].float(), 9, 1, 4)[0, 0] > 0.5
    normals = maps.normals[inner]
    mean = F.normalize(normals.mean(0), dim=0)
    return float(torch.rad2deg(torch.acos((normals @ mean).clamp(-1, 1))).quantile(0.9))


def test_slabs_are_shallow_where_reliefs_are_steep():
    for index in range(6):
        assert interior_tilt("slab", index) < 25
        assert interior_tilt("relief", index) > 35


@pytest.mark.parametrize("layout", LAYOUTS)
def test_light_layouts_give_unit_directions_toward_the_camera(layout):
    lights = draw_lights({layout: 1.0}, 64, 60.0, sample_generator(1, 2))
    assert lights.shape == (64, 3)
    torch.testing.assert_close(lights.norm(dim=-1), torch.ones(64))
    assert (lights[:, 2] > 0).all()
    if layout == "cap":
        assert (lights[:, 2] >= math.cos(math.radians(60)) - 1e-6).all()
    if layout == "ring":
        assert len(torch.unique(lights[:, 2].round(decimals=5))) <= 3
    if layout == "panel":                       # lamps evenly spaced on a board: a grid in tangents
        tangents = lights[:, :2] / lights[:, 2:]
        distances = torch.cdist(tangents, tangents) + torch.eye(64) * 1e9
        nearest = distances.min(dim=1).values
        assert float(nearest.max() / nearest.min()) < 1.25


def test_a_dataset_iterates_over_its_length_and_no_further():
    data = LightDataset(3, resolution=32, images=4)
    assert len(list(data)) == 3
    with pytest.raises(IndexError):
        data[3]


def test_quantisation_matches_reading_the_same_data_from_files(tmp_path):
    values = np.random.default_rng(0).random((16, 16, 3)).astype(np.float32)
    values[0, 0] = 0.0
    write_png16(tmp_path / "deep.png", values)
    deep = cv2.imread(str(tmp_path / "deep.png"), cv2.IMREAD_UNCHANGED)
    cv2.imwrite(str(tmp_path / "crop.png"), (deep // 256).astype(np.uint8))         # DiLiGenT's crops
    cv2.imwrite(str(tmp_path / "camera.png"), np.round(values[..., ::-1] * 255).astype(np.uint8))
    as_read = {"round16": read_image(tmp_path / "deep.png", "round"),
               "floor8": read_image(tmp_path / "crop.png", "floor"),
               "round8": read_image(tmp_path / "camera.png", "round")}
    for storage, read in as_read.items():
        np.testing.assert_allclose(quantize(torch.from_numpy(values), storage).numpy(), read,
                                   rtol=0, atol=1e-7, err_msg=storage)
    floor_as_round = read_image(tmp_path / "crop.png", "round")
    assert not np.allclose(quantize(torch.from_numpy(values), "floor8").numpy(), floor_as_round)


def test_the_camera_saturates_at_full_scale_and_stores_levels():
    images = torch.rand(4, 3, 32, 32) * 2                      # 99th percentile near 2
    fixed = dict(exposure=(0.0, 0.0), read_noise=0.0, shot_noise=0.0)
    for storage in FORMATS:
        camera = Camera(**fixed, formats={storage: 1.0})
        out = record(images, expose(camera, images.shape, sample_generator(0, 0)))
        assert out.min() >= 0 and out.max() <= 255.5 / 255            # floor8 reads 255 as 255.5
        assert (out[images >= 1.01] >= 254 / 255).all()       # over full scale: saturated
        if storage == "round8":
            torch.testing.assert_close(out * 255, (out * 255).round())
    dim = record(images, expose(Camera(exposure=(-2.0, -2.0), read_noise=0.0, shot_noise=0.0,
                                       formats={"round8": 1.0}), images.shape, sample_generator(0, 0)))
    brightest = round(float(images.max()) * 0.01 * 255)       # two decades down: a few levels left
    assert brightest <= 5 and float(dim.max()) == pytest.approx(brightest / 255)


def test_a_dataset_with_every_family_layout_and_the_camera():
    ds = LightDataset(8, resolution=64, images=8, shapes=dict.fromkeys(SHAPES, 1.0),
                      layouts=dict.fromkeys(LAYOUTS, 1.0), camera=Camera(), seed=5)
    for index in range(8):
        item = ds[index]
        assert torch.isfinite(item["images"]).all() and item["images"].max() <= 255.5 / 255
        assert item["mask"].sum() > 0 and (item["directions"][:, 2] > 0).all()
    forced = LightDataset(2, resolution=64, images=8, shape="vessel", seed=5)[0]
    assert forced["mask"].sum() > 0


def test_bad_shape_and_layout_settings():
    with pytest.raises(InputError, match="unknown \\['teapot'\\]"):
        LightDataset(2, resolution=32, shapes={"teapot": 1.0})
    with pytest.raises(InputError, match="not all 0"):
        LightDataset(2, resolution=32, layouts={"cap": 0.0})
    with pytest.raises(InputError, match="shape family 'cube' unknown"):
        LightDataset(2, resolution=32, shape="cube")


def test_paint_lays_a_few_flat_colours_over_the_same_scene():
    from unps.lightnet.materials import painted

    albedo = painted(64, sample_generator(0, 5))
    colours = torch.unique(albedo.reshape(-1, 3), dim=0)
    assert 2 <= len(colours) <= 4 and (albedo >= 0.05).all() and (albedo <= 1).all()
    common = dict(resolution=64, images=4, camera=None, perturbation=0.0, saturation=None, texture=0.0)
    plain = LightDataset(8, **common)
    paint = LightDataset(8, paint=1.0, **common)
    for index in range(8):
        a, b = plain[index], paint[index]
        torch.testing.assert_close(a["directions"], b["directions"])   # the same scene …
        lit = (a["images"] > 1e-3) & (b["images"] > 1e-3)
        ratio = (b["images"][lit] / a["images"][lit]).round(decimals=3)
        assert 2 <= len(torch.unique(ratio)) <= 12                   # … under a few flat colours


def test_a_second_material_lies_in_patches_over_the_same_scene():
    """Where the second material's coat is not, the sample is the one-material sample (up to the
    stack's level); under it, another material: half of them dark."""
    common = dict(resolution=64, images=4, camera=None, perturbation=0.0, saturation=None, texture=0.0,
                  materials=MaterialBank(measured=1.0))
    plain, two = LightDataset(8, **common), LightDataset(8, second_material=1.0, **common)
    shares, darkening = [], []
    for index in range(8):
        scene, a, b = two.draw(index), plain[index], two[index]
        torch.testing.assert_close(a["directions"], b["directions"])
        lit = (a["images"] > 1e-3) & (b["images"] > 1e-3)
        coat = scene.coat.bool().expand_as(lit)
        level = (b["images"][lit & ~coat] / a["images"][lit & ~coat])
        torch.testing.assert_close(level, torch.full_like(level, float(level.median())))
        under = b["images"][lit & coat] / a["images"][lit & coat]
        assert float(under.std() / under.mean()) > 0.05                 # another material there
        shares.append(float(scene.coat[scene.maps.mask].mean()))
        darkening.append(float(scene.second.diffuse.max() / scene.brdf.diffuse.max()))
    assert all(0 < share < 1 for share in shares) and 0.1 < np.mean(shares) < 0.9
    assert min(darkening) < 0.1
    assert all(plain.draw(index).second is None for index in range(8))


def test_narrowed_intensities_draw_stacks_from_equal_lamps_to_the_whole_range():
    """A narrowed stack's intensities spread over a part of U(0.2, 2) drawn per stack, down to
    every lamp alike; the scene's lights are the same draws; the rest keep the whole range."""
    common = dict(resolution=32, images=16, camera=None)
    plain, narrowed = LightDataset(24, **common), LightDataset(24, narrowed_intensities=1.0, **common)
    ratios = {}
    for name, dataset in (("plain", plain), ("narrowed", narrowed)):
        scenes = [dataset.draw(index) for index in range(24)]
        assert all(((s.intensities >= 0.2) & (s.intensities <= 2.0)).all() for s in scenes)
        ratios[name] = [float(s.intensities.max() / s.intensities.min()) for s in scenes]
    for index in range(24):
        torch.testing.assert_close(plain.draw(index).lights, narrowed.draw(index).lights)
    assert min(ratios["plain"]) > 2.5
    assert min(ratios["narrowed"]) < 1.3 and np.median(ratios["narrowed"]) < np.median(ratios["plain"])
    half = LightDataset(24, narrowed_intensities=0.5, **common)
    half_ratios = [float(half.draw(i).intensities.max() / half.draw(i).intensities.min()) for i in range(24)]
    assert sum(r < 2.5 for r in half_ratios) not in (0, 24)
    with pytest.raises(InputError, match="narrowed_intensities is a share"):
        LightDataset(2, resolution=32, narrowed_intensities=1.5)


def test_a_room_adds_the_same_light_to_every_captured_image():
    """The room's light is the same in every image before the lights' intensities divide it, and
    its level the stack's mean image (each divided by its light's) times the level drawn."""
    g = torch.Generator().manual_seed(0)
    images, intensities = torch.rand(2, 5, 3, 8, 8, generator=g), 0.2 + torch.rand(2, 5, generator=g)
    level = torch.tensor([0.0, 0.03])
    lit = with_room_light(images, intensities, level)
    added = lit - images                                                          # (2, 5, 3, 8, 8)
    assert torch.equal(added[0], torch.zeros_like(added[0]))
    torch.testing.assert_close(added[1], added[1, :1].expand_as(added[1]))
    torch.testing.assert_close(added[1, 0], 0.03 * (images[1] / intensities[1, :, None, None, None]).mean(0))
    torch.testing.assert_close(with_room_light(images[1], intensities[1], level[1]), lit[1])


def test_room_light_draws_a_level_for_its_share_of_the_samples_and_the_batch_renders_it_as_alone():
    common = dict(resolution=32, images=6, camera=None, seed=4)
    plain, lit = LightDataset(16, **common), LightDataset(16, room_light=1.0, **common)
    assert all(plain.draw(i).room == 0 for i in range(16))
    rooms = [lit.draw(i).room for i in range(16)]
    assert all(0 < room <= ROOM_LIGHT_MAX for room in rooms)
    for index in range(16):
        torch.testing.assert_close(plain.draw(index).lights, lit.draw(index).lights)
    half = [LightDataset(16, room_light=0.5, **common).draw(i).room for i in range(16)]
    assert sum(room > 0 for room in half) not in (0, 16)
    scenes = [lit.draw(i) for i in range(4)]
    alone = default_collate([render(scene, torch.device("cpu")) for scene in scenes])
    assert_same_stacks(render_batch(SceneBatch.of(scenes), torch.device("cpu"))["images"], alone["images"])
    inside = scenes[0].maps.mask
    noise = scenes[0].perturbation[:, :, inside]
    dark = render(dataclasses.replace(scenes[0], room=0.0), torch.device("cpu"))["images"][:, :, inside]
    unlit = (dark - noise).abs() < 1e-7                                           # no light at all
    assert unlit.float().mean() > 0.05
    assert ((alone["images"][0][:, :, inside] - dark)[unlit] > 0).float().mean() > 0.9
    with pytest.raises(InputError, match="room_light is a share"):
        LightDataset(2, resolution=32, room_light=2.0)


def test_a_darkened_material_keeps_its_lobes():
    brdf = AnalyticBRDF([0.5, 0.4, 0.3], [[0.2, 0.2, 0.2], [0.1, 0.1, 0.1]], (0.1, 0.4), (0.04, 0.05))
    dark = darkened(brdf, 0.01)
    torch.testing.assert_close(dark.diffuse, brdf.diffuse * 0.01)
    assert torch.equal(dark.specular, brdf.specular) and dark.roughness == brdf.roughness
    assert dark.fresnel0 == brdf.fresnel0
    neural = tiny_neural_brdf(0)
    assert darkened(neural, 0.01) is neural


def test_jars_render_the_same_on_one_thread_and_on_two():
    """Points tied for the nearest in a pixel: the last is kept, not whichever thread wrote last."""
    before = torch.get_num_threads()
    try:
        stacks = []
        for threads in (1, 2):
            torch.set_num_threads(threads)
            stacks.append([LightDataset(4, resolution=64, images=4, shape="jar", seed=2)[i]["images"]
                           for i in range(4)])
    finally:
        torch.set_num_threads(before)
    assert all(torch.equal(a, b) for a, b in zip(*stacks))


SCENE = dict(resolution=64, images=6, shapes=dict.fromkeys(SHAPES, 1.0), layouts=dict.fromkeys(LAYOUTS, 1.0),
             camera=Camera(), paint=0.5, second_material=0.5, interreflection=0.5, seed=11)


def test_samples_drawn_in_a_worker_and_rendered_as_a_batch_are_the_samples():
    """The GPU route of the training data (draws in the workers, the batch rendered at once in the
    training process), taken on the CPU: the samples the CPU route gives, to float rounding (a value
    on the edge of a storage level may round to its neighbour)."""
    dataset = LightDataset(4, **SCENE)
    draws = DataLoader(Draws(dataset), batch_size=4, num_workers=1, collate_fn=SceneBatch.of)
    scenes = next(iter(draws))
    assert isinstance(scenes, SceneBatch) and scenes.normals.shape == (4, 64, 64, 3)
    rendered = render_batch(scenes, torch.device("cpu"))
    plain = next(iter(DataLoader(dataset, batch_size=4)))
    assert all(torch.equal(rendered[key], plain[key]) for key in plain if key != "images")
    assert_same_stacks(rendered["images"], plain["images"])


def test_the_gpu_route_of_the_training_loader_taken_on_the_cpu():
    """A data module told its stacks are rendered on a GPU: its loader hands over packed draws with
    the camera noise left to a seed, and its transfer hook renders them where it is asked."""
    with initialize_config_module(config_module="unps.conf", version_base="1.3"):
        cfg = compose("train", overrides=["recipe.resolution=32", "recipe.images=4", "recipe.batch_size=3",
                                          "recipe.workers=1"])
    data = LightData(cfg.recipe, cfg.data, cfg.seed, device=torch.device("cuda"))   # a name only
    data.setup("fit")
    draws = next(iter(data.train_dataloader()))
    assert isinstance(draws, SceneBatch) and all(isinstance(seed, int) for seed in draws.exposures.noise)
    batch = data.transfer_batch_to_device(draws, torch.device("cpu"), 0)
    assert batch["images"].shape == (3, 4, 3, 32, 32) and batch["family"].shape == (3,)
    assert torch.isfinite(batch["images"]).all() and batch["images"].max() <= 1 + 0.5 / 255   # floor8 reads k + ½


def test_pinning_a_batch_reaches_every_tensor_in_it_and_keeps_the_rest():
    """SceneBatch.pin_memory maps each tensor, in the batch and in its shadow plan and lobe table
    (the loader's pin-memory thread calls it); taken here with a copy in place of pinning, which
    needs a GPU."""
    dataset = LightDataset(3, **SCENE)
    batch = SceneBatch.of([dataset.draw(i) for i in range(3)])
    copied = map_tensors(batch, torch.clone)
    pairs = [(getattr(batch, f.name), getattr(copied, f.name)) for f in dataclasses.fields(batch)]
    pairs += [(getattr(part(batch), f.name), getattr(part(copied), f.name))
              for part in (lambda b: b.shadows, lambda b: b.lobes) for f in dataclasses.fields(part(batch))]
    tensors = [(a, b) for a, b in pairs if isinstance(a, torch.Tensor)]
    assert len(tensors) >= 15
    assert all(a is not b and torch.equal(a, b) for a, b in tensors)
    kept = [(a, b) for a, b in pairs if not isinstance(a, (torch.Tensor, tuple)) and not dataclasses.is_dataclass(a)]
    assert kept and all(a is b for a, b in kept)
    assert_same_stacks(render_batch(copied, torch.device("cpu"))["images"],
                       render_batch(batch, torch.device("cpu"))["images"])


def test_loader_workers_default_to_every_cpu_but_two_and_refuse_a_negative_count():
    assert (loader_workers(None, 16), loader_workers(None, 1), loader_workers(0, 16)) == (14, 0, 0)
    with pytest.raises(InputError, match="recipe.workers must be a whole number"):
        loader_workers(-1, 16)


def assert_same_stacks(a: torch.Tensor, b: torch.Tensor) -> None:
    """Equal to float rounding: a few values one storage level apart at most."""
    assert a.shape == b.shape
    differ = (a - b).abs()
    assert float(differ.max()) <= 1 / 255 + 1e-6 and float((differ > 1e-5).float().mean()) < 1e-4


def tiny_neural_brdf(seed: int) -> NeuralBRDF:
    """A made-up neural material of the MERL fits' shape (6→21→21→3), its outputs of order one."""
    rng = np.random.default_rng(seed)
    sizes = [(6, 21), (21, 21), (21, 3)]
    return NeuralBRDF([(0.3 * rng.standard_normal(size).astype(np.float32),
                        np.full(size[1], 0.1, np.float32)) for size in sizes])


@pytest.mark.parametrize("camera", [Camera(), None], ids=["camera", "perturbation"])
def test_a_batch_renders_each_scene_as_it_renders_alone(camera):
    """Analytic materials of one and two lobes, a neural one, painted and plain albedo, one material
    and two (a neural second among them), the camera's noise drawn or left to the renderer (a seed):
    the batch is each scene's render, stacked."""
    dataset = LightDataset(6, **{**SCENE, "camera": camera, "seed": 5}, materials=MaterialBank(measured=1.0))
    scenes = [dataset.draw(i) for i in range(6)]
    scenes[1] = dataclasses.replace(scenes[1], brdf=tiny_neural_brdf(1), family="neural")
    scenes[5] = dataclasses.replace(scenes[5], second=tiny_neural_brdf(2),
                                    coat=coated(64, sample_generator(9, 0)) * scenes[5].maps.mask)
    assert {scene.second is None for scene in scenes} == {True, False}
    if camera is not None:
        scenes[2:4] = [dataclasses.replace(s, exposure=dataclasses.replace(s.exposure, noise=7 + i))
                       for i, s in enumerate(scenes[2:4])]
    assert {len(s.brdf.specular) for s in scenes if s.family != "neural"} == {1, 2}
    alone = default_collate([render(scene, torch.device("cpu")) for scene in scenes])
    batch = render_batch(SceneBatch.of(scenes), torch.device("cpu"))
    assert all(torch.equal(batch[key], alone[key]) for key in alone if key != "images")
    assert_same_stacks(batch["images"], alone["images"])


def test_noise_left_to_the_renderer_keeps_every_other_draw_of_the_camera():
    camera, shape = Camera(), (4, 3, 32, 32)
    drawn = expose(camera, shape, sample_generator(0, 5))
    left = expose(camera, shape, sample_generator(0, 5), defer_noise=True)
    assert (left.gain, left.shot, left.read) == (drawn.gain, drawn.shot, drawn.read)
    assert isinstance(left.noise, int) and left.storage in FORMATS
    noise = stack_noise((left.noise, 3), torch.Size(shape), torch.device("cpu"))
    fresh = torch.randn(shape, generator=torch.Generator().manual_seed(left.noise))
    assert torch.equal(noise[0], fresh) and torch.equal(noise[1], stack_noise((3,), shape, torch.device("cpu"))[0])
    noise = noise[0]
    assert abs(float(noise.mean())) < 0.05 and abs(float(noise.std()) - 1) < 0.05
    images = torch.rand(shape) * 0.5
    assert torch.equal(record(images, left), record(images, left))


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU")
def test_a_sample_rendered_on_a_gpu_is_the_cpu_sample_to_float_rounding():
    """Without the camera every draw is the CPU's: the GPU's samples are the CPU's. With it, the GPU
    draws the noise itself: one batch is each sample rendered alone on the GPU."""
    plain = {**SCENE, "camera": None}
    on_cpu, on_gpu = LightDataset(6, **plain), LightDataset(6, **plain, device=torch.device("cuda"))
    for index in range(6):
        a, b = on_cpu[index], on_gpu[index]
        assert b["images"].device.type == "cuda"
        assert torch.equal(a["directions"], b["directions"].cpu())
        assert_same_stacks(a["images"], b["images"].cpu())
    with_camera = LightDataset(6, **SCENE, device=torch.device("cuda"))
    scenes = [with_camera.draw(i) for i in range(6)]
    assert all(isinstance(scene.exposure.noise, int) for scene in scenes)
    data = LightData(OmegaConf.create({"resolution": 64, "images": 6, "batch_size": 3, "max_steps": 1,
                                       "val_samples": 3, "workers": 0}), None, 11, device=torch.device("cuda"))
    batch = data.transfer_batch_to_device(SceneBatch.of(scenes), torch.device("cuda"), 0)
    assert batch["images"].shape == (6, 6, 3, 64, 64)
    assert all(batch[key].device.type == "cuda" for key in batch)
    alone = torch.stack([with_camera[i]["images"] for i in range(6)])
    assert_same_stacks(batch["images"].cpu(), alone.cpu())
    pinned = SceneBatch.of(scenes).pin_memory()
    assert pinned.normals.is_pinned() and pinned.shadows.depth.is_pinned() and pinned.lobes.diffuse.is_pinned()
    assert pinned.exposures.gain.is_pinned()
    assert all(pick.is_pinned() for pick in pinned.exposures.picks if pick.numel())   # an empty one has
    # no memory to pin (a storage format no sample of the batch drew)
    again = render_batch(pinned, torch.device("cuda"))
    assert all(torch.equal(again[key], batch[key]) for key in batch)

"""One fit, from its configuration to its run folder: read and check the subject, resolve the
lights, run the method, integrate the depth and write every output (:mod:`unps.pipeline.outputs`).
"""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any

from hydra.utils import instantiate
import numpy as np
from omegaconf import DictConfig, OmegaConf

from unps.allocator import keep_freed_memory
from unps.data.checks import check_light_span, collected_warnings, usable_subject
from unps.data.lights import Verdict
from unps.data.prepare import add_noise
from unps.data.subject import Subject
from unps.device import describe, peak_memory_gb, resolve_device
from unps.errors import InputError
from unps.geometry import integrate_normals
from unps.lights import Lights, ground_truth, light_errors, with_lights
from unps.lights.stages import record
from unps.metrics import angular_error, normal_metrics
from unps.threads import set_fit_threads
from unps.timing import recording, stage

log = logging.getLogger("unps.fit")   # the name users see in the log


def launcher_config() -> dict | None:
    """The Hydra launcher's settings when this fit is one job of a multirun, else None."""
    from hydra.core.hydra_config import HydraConfig
    from hydra.types import RunMode

    if not HydraConfig.initialized() or HydraConfig.get().mode != RunMode.MULTIRUN:
        return None
    return OmegaConf.to_container(HydraConfig.get().launcher, resolve=True)


def build(node: DictConfig, **settled) -> tuple[str, Any]:
    """Instantiate a config-group node; its ``name`` labels it and is not passed to the target
    (nor is ``refine``, which the light settings hold for the method rather than the estimator).
    ``settled`` replaces the node's values of those keys that it has.

    Nodes are partial (``_partial_: true``): the callable they give raises its own errors
    when called, rather than Hydra's wrapped instantiation error.
    """
    spec = OmegaConf.to_container(node, resolve=True)
    name = spec.pop("name")
    spec.pop("refine", None)
    spec.update({key: value for key, value in settled.items() if key in spec})
    return name, instantiate(spec)


def learns_lights(light: DictConfig, method: DictConfig) -> bool:
    """Whether the method learns the lights with the surface, as ``light.refine`` says: ``true``
    (``light=refine``: the method must be one that can, method=unps), ``auto`` (``light=selfcal``:
    where the method can) or ``false`` (absent: the same).

    Raises:
        InputError: ``light.refine`` is true and the method cannot learn lights, or it is none of
            true, false, auto.
    """
    refine = light.get("refine", False)
    can = "refine_lights" in method
    if refine not in (True, False, "auto"):
        raise InputError(f"light.refine={refine}: expected true, false or auto")
    if refine is True and not can:
        raise InputError(f"light=refine refines the lights inside the neural inverse rendering, "
                         f"so it needs method=unps, not method={method.name}")
    if refine == "auto" and not can:
        log.info("method=%s takes the lights as the light stages leave them (light.refine=auto: "
                 "method=unps would learn them further with the surface)", method.name)
    return bool(refine) and can


def fit(cfg: DictConfig) -> dict:
    """Run one method on one subject and write every output into ``cfg.paths.output_dir``.

    The subject is read and validated and the lights resolved before anything is written.

    Returns:
        The metrics also written to ``metrics.json``, with the seconds of each stage so far
        (``stage_seconds``, :mod:`unps.timing`) and every warning logged (``warnings``,
        :mod:`unps.data.checks`).
    """
    with recording() as seconds, collected_warnings() as warnings:
        return run_fit(cfg, seconds, warnings)


def without_pixels(subject: Subject) -> Subject:
    """``subject`` with its images replaced by zeros that take no memory (a broadcast view of one
    value), all else kept: what the run still needs of the subject as read once the method has its
    own copy of the images divided by other lights is its lights, which the lights it ends with are
    compared to (the images of 12 photographs of 20 MP are 2.9 GB)."""
    return subject.replace(images=np.broadcast_to(np.zeros((), np.float32), subject.images.shape))


def read_subject(cfg: DictConfig) -> Subject:
    """The subject ``cfg.subject`` names, read (timed as the ``reading`` stage) and checked.

    Raises:
        InputError: a value the subject needs is not given, or the images cannot be used
            (:func:`unps.data.checks.usable_subject`).
    """
    missing = sorted(OmegaConf.missing_keys(cfg.subject))
    if missing:
        raise InputError("this subject needs " + ", ".join(f"{key}=…" for key in missing)
                         + " on the command line (e.g. subject.root=<folder of images>)")
    with stage("reading"):
        subject = instantiate(cfg.subject, _partial_=True)()   # called here so errors reach the user
    return usable_subject(subject)


def with_fit_verdict(lights: Lights, directions: np.ndarray, scales: np.ndarray, truth: Subject) -> Lights:
    """The lights the fit ended with: ``directions`` (n, 3) and ``lights``' intensities (ones if it
    has none) times ``scales`` (n,), with the fit's verdict (how far it moved the directions, and
    their error where ``truth`` is calibrated) after the light stages' verdicts."""
    intensities = (lights.intensities if lights.intensities is not None
                   else np.ones_like(lights.directions)) * scales[:, None]
    moved = float(angular_error(directions, lights.directions).mean())
    return record(Lights(directions, intensities.astype(np.float32), "refined",
                         spread_deg=lights.spread_deg, verdicts=lights.verdicts),
                  Verdict("fit", "changed", f"learnt with the surface; directions moved "
                          f"{moved:.2f}° on average", {"moved_deg": moved}), truth)


def run_fit(cfg: DictConfig, seconds: dict[str, float], warnings: list[str]) -> dict:
    """:func:`fit`'s body; ``seconds`` and ``warnings`` fill as it goes."""
    from lightning import seed_everything

    from unps.pipeline.outputs import write_fit_outputs

    if isinstance(cfg.seed, bool) or not isinstance(cfg.seed, int):
        raise InputError(f"seed must be a whole number, got {cfg.seed!r}")
    seed_everything(cfg.seed, workers=True, verbose=False)
    threads, source = set_fit_threads(cfg.get("threads"), launcher_config())
    device = resolve_device(cfg.device)                   # checked before anything is read
    keep_freed_memory()
    out = Path(cfg.paths.output_dir)
    start = time.perf_counter()
    subject, noise_reference = add_noise(read_subject(cfg), cfg.noise, seed=cfg.seed)
    original = subject
    light_name, light_source = build(cfg.light)
    method_name, method = build(cfg.method, refine_lights=learns_lights(cfg.light, cfg.method))
    with stage("lights"):
        lights = light_source(subject)
    condition = check_light_span(lights.directions, f"the lights of {subject.name!r} ({light_name})",
                                 estimated=lights.source != "gt")
    light_metrics = {}
    if lights.source != "gt":
        light_metrics = light_errors(lights, subject)
        subject = with_lights(subject, lights)
        original = without_pixels(original)
    h, w = subject.resolution
    log.info("%s: %d images, %d×%d pixels (%d on the object), read in %.1f s; lights: %s; "
             "method: %s; device %s, %d torch threads (%s)", subject.name, subject.n_images, w, h,
             subject.mask.sum(), time.perf_counter() - start, light_name, method_name, describe(device),
             threads, source)

    start = time.perf_counter()
    with stage("method"):
        estimate = method(subject, lights.directions)
    with stage("depth"):
        depth = integrate_normals(estimate.normals, subject.mask)
    runtime = time.perf_counter() - start
    if estimate.light_directions is not None:
        lights = with_fit_verdict(lights, estimate.light_directions, estimate.light_scales, original)
        light_metrics = dict(lights.verdicts[-1].errors)

    metrics = {"study": cfg.get("study"), "seed": cfg.seed,
               "subject": subject.name, "method": method_name, "light": light_name,
               "noise": cfg.noise, "noise_reference": noise_reference,
               "runtime_s": runtime, "n_images": subject.n_images, "resolution": [h, w],
               "device": describe(device), "gpu_peak_gb": peak_memory_gb(device),
               **light_metrics}
    metrics.update(estimate.info)
    error = None
    if subject.normals is not None:
        error = angular_error(estimate.normals, subject.normals)
        metrics.update(normal_metrics(estimate.normals, subject.normals, subject.mask))
        log.info("normal error: mean %.2f°, median %.2f°, %.1f%% under 11.25°, slant bias %+.2f° "
                 "(%.2f s)", metrics["normal_mae"], metrics["normal_median"], 100 * metrics["acc_11_25"],
                 metrics["slant_bias"], runtime)
    true_lights = ground_truth(original) if lights.source != "gt" and original.calibrated else None
    if lights.spread_deg is not None:
        metrics["light_spread_deg"] = float(np.median(lights.spread_deg))
    if lights.verdicts:
        metrics["light_stages"] = [verdict.to_dict() for verdict in lights.verdicts]
    metrics["light_condition"] = condition if np.isfinite(condition) else None
    metrics["warnings"] = list(warnings)
    metrics["stage_seconds"] = dict(seconds)
    with stage("writing"):
        write_fit_outputs(out, subject, estimate, depth, lights, metrics, error, true_lights)
    return metrics

"""The random generators of a fit, saved in its checkpoints so that a resumed fit continues
exactly as the uninterrupted one would have."""

from __future__ import annotations

import torch


def rng_state(device: torch.device) -> dict:
    """The generators behind the input noise and the image and pixel draws: a resumed fit
    continues exactly as the uninterrupted one would have."""
    return {"cpu": torch.get_rng_state(),
            "cuda": torch.cuda.get_rng_state(device) if device.type == "cuda" else None}


def restore_rng(state: dict, device: torch.device) -> None:
    """Put back the generators :func:`rng_state` saved."""
    torch.set_rng_state(state["cpu"])
    if state["cuda"] is not None and device.type == "cuda":
        torch.cuda.set_rng_state(state["cuda"], device)

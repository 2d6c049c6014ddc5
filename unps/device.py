"""Where a run's tensors live: the ``device=auto|cpu|cuda`` option of ``unps.fit`` and ``unps.train``.

``auto`` takes the first CUDA GPU when torch sees one, else the CPU. Every stage that can run on
a GPU (the light network, the light stages, the robust initialisation, the fit and its
interreflection update, the training data) takes the device from this one option, so a run is
wholly on one device. On the CPU, every stage computes exactly what it computed before the option
existed (``experiments/speed/same_outputs.py``).
"""

from __future__ import annotations

import re

import torch

from unps.errors import InputError

CHOICES = "auto, cpu, cuda or cuda:<index>"


def resolve_device(name: str | torch.device) -> torch.device:
    """The torch device that ``device=name`` means on this machine.

    Example:
        >>> resolve_device("cpu")
        device(type='cpu')

    Raises:
        InputError: a name other than auto, cpu, cuda, cuda:<index>; CUDA asked for where torch
            sees none, or an index beyond the GPUs it sees.
    """
    if isinstance(name, torch.device):
        name = str(name)
    if not isinstance(name, str) or not re.fullmatch(r"auto|cpu|cuda(:\d+)?", name):
        raise InputError(f"device must be {CHOICES}; got {name!r}")
    if name == "auto":
        return torch.device("cuda:0" if torch.cuda.is_available() else "cpu")
    if name == "cpu":
        return torch.device("cpu")
    if not torch.cuda.is_available():
        raise InputError(f"device={name}, but torch {torch.__version__} sees no CUDA GPU (a CPU-only "
                         f"build, or no driver); use device=auto or device=cpu")
    device = torch.device(name if ":" in name else "cuda:0")
    if device.index >= torch.cuda.device_count():
        raise InputError(f"device={name}, but torch sees {torch.cuda.device_count()} CUDA GPU(s) "
                         f"(cuda:0…cuda:{torch.cuda.device_count() - 1})")
    return device


def trainer_placement(device: torch.device) -> dict:
    """The Lightning ``Trainer`` arguments that put its module on ``device``.

    Example:
        >>> trainer_placement(torch.device("cpu"))
        {'accelerator': 'cpu', 'devices': 1}
        >>> trainer_placement(torch.device("cuda:1"))
        {'accelerator': 'gpu', 'devices': [1]}
    """
    if device.type == "cuda":
        return {"accelerator": "gpu", "devices": [device.index or 0]}
    return {"accelerator": "cpu", "devices": 1}


def to_device(tensor: torch.Tensor, device: torch.device) -> torch.Tensor:
    """``tensor`` on ``device``, the copy queued rather than waited for: a CPU tensor bound for a
    GPU goes from page-locked memory (one already there as it is). A copy from ordinary memory
    holds the CPU until the GPU has reached it in its queue, so the CPU cannot queue the next
    batch's work while the GPU runs this one's.

    Example:
        >>> to_device(torch.ones(2), torch.device("cpu"))
        tensor([1., 1.])
    """
    if device.type == "cuda" and tensor.device.type == "cpu" and not tensor.is_pinned():
        tensor = tensor.pin_memory()
    return tensor.to(device, non_blocking=True)


def native_bfloat16(device: torch.device) -> bool:
    """Whether ``device`` computes bfloat16 convolutions in hardware: a CUDA GPU, or a CPU with
    AMX tiles (Intel Xeon since Sapphire Rapids) or AVX512-BF16 instructions (AMD EPYC since Zen 4,
    Intel Xeon since Cooper Lake), by torch's own checks. Elsewhere oneDNN emulates them: a 2-core
    CPU without either ran the fit's networks 6× slower in bfloat16 than in float32; a 2-core Intel
    Xeon with AMX ran them in 0.7–0.8× the time, a 2-core AMD EPYC with AVX512-BF16 in 0.65×
    (``experiments/speed/README.md``)."""
    if device.type == "cuda":
        return True
    if device.type != "cpu":
        return False
    names = ("_is_amx_tile_supported", "_is_avx512_bf16_supported")
    checks = [getattr(torch.cpu, name, None) for name in names]
    return any(check is not None and bool(check()) for check in checks)


def peak_memory_gb(device: torch.device) -> float | None:
    """The most GPU memory torch has held on ``device`` since the process started, in GiB; None on
    the CPU."""
    if device.type != "cuda":
        return None
    return torch.cuda.max_memory_allocated(device) / 2 ** 30


def describe(device: torch.device) -> str:
    """The device as a log line names it: ``cpu`` or ``cuda:0 (NVIDIA H100 80GB HBM3)``."""
    if device.type == "cuda":
        return f"{device} ({torch.cuda.get_device_name(device)})"
    return str(device)

"""The checks a fit runs on the images before its first step: memory beyond the stack, and time.

    python experiments/speed/start_checks.py                       # 96 images of 1 MP, 8-bit
    python experiments/speed/start_checks.py --images 12 --megapixels 5

Each check (:mod:`unps.data.checks`, and the headroom of values read as 0,
:func:`unps.inverse.grids.black_headroom`) reads the whole stack, as captured, once or twice. On
a stack of a user's size a copy of it is gigabytes, so the peak of what each allocates beyond the
stack (``tracemalloc``, which numpy reports to) is printed with its wall time. The stack is drawn,
not read: a dark 8-bit capture (values floored to k/255, many pixels black or nearly so, a few
values at the top level; the shares are printed), 90 % of the frame on the object, seeded.
"""

from __future__ import annotations

import argparse
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from stages import machine  # noqa: E402

from unps.data.checks import black_everywhere, clipped_values, faintly_lit, value_levels, zero_ceiling  # noqa: E402
from unps.inverse.grids import black_headroom  # noqa: E402


def dark_capture(images: int, megapixels: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(n, H, W, 3) float32 8-bit values floored (k / 255) and the (H, W) bool object mask."""
    side = int(round(np.sqrt(megapixels * 1e6)))
    rng = np.random.default_rng(seed)
    albedo = rng.random((side, side, 1), np.float32) ** 4
    stack = np.empty((images, side, side, 3), np.float32)
    for image in stack:                                     # image by image: no float64 copy
        image[:] = np.floor(np.minimum(rng.gamma(0.3, 20, (side, side, 3)) * albedo * 4, 255)) / 255
    mask = np.ones((side, side), bool)
    mask[: side // 10] = False
    return stack, mask


def measured(check, *args):
    """``check(*args)``, the peak GB it allocated beyond what was held before, and its seconds."""
    tracemalloc.start()
    start = time.perf_counter()
    result = check(*args)
    seconds = time.perf_counter() - start
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return result, peak / 2 ** 30, seconds


def share(result, mask: np.ndarray) -> str:
    """What a check found, in words: the share of the object it marks, or its value."""
    if isinstance(result, tuple):                                       # value_levels' two shares
        return f"clipped {result[0].mean():.2%}, black {result[1].mean():.2%} of the values"
    if isinstance(result, np.ndarray) and result.dtype == bool:
        return f"{result[:, mask].mean() if result.ndim == 3 else result[mask].mean():.2%} of the object"
    if isinstance(result, np.ndarray):
        return f"headroom on {(result > 0).mean():.2%} of the values"
    return f"{result * 255:.2f}/255"


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--images", type=int, default=96)
    parser.add_argument("--megapixels", type=float, default=1.0)
    args = parser.parse_args(argv)
    if args.images < 1 or args.megapixels <= 0:
        parser.error(f"--images {args.images} --megapixels {args.megapixels}: both positive")
    stack, mask = dark_capture(args.images, args.megapixels)
    print(f"machine: {machine()}")
    print(f"{args.images} images of {mask.shape[1]}×{mask.shape[0]}, 8-bit floored: the stack "
          f"{stack.nbytes / 2 ** 30:.2f} GB (float32)")
    ceiling = zero_ceiling(stack, mask)
    checks = {"clipped_values": (clipped_values, stack, mask),
              "value_levels": (value_levels, stack, mask),
              "black_everywhere": (black_everywhere, stack, mask),
              "faintly_lit": (faintly_lit, stack, mask),
              "zero_ceiling": (zero_ceiling, stack, mask),
              "black_headroom (×4 grid)": (black_headroom, stack, mask, 4, ceiling, None)}
    print(f"{'check':<26}{'peak GB':>8}{'s':>7}  found")
    for name, (check, *inputs) in checks.items():
        result, peak, seconds = measured(check, *inputs)
        print(f"{name:<26}{peak:8.2f}{seconds:7.1f}  {share(result, mask)}", flush=True)


if __name__ == "__main__":
    main()

"""Which operations, and which convolutions, take a fit's steps (``torch.profiler``).

    python experiments/speed/ops.py                                  # ball, 80 steps, fast, light=gt
    python experiments/speed/ops.py --subject pot1 --steps 200
    python experiments/speed/ops.py --set preset.images_per_step=8 preset.pixel_keep=0.8

:mod:`stages` says which stage of a fit the seconds go to; this says which of torch's
operations inside them: one short fit of ``--subject`` (``method=unps preset=fast light=gt``
and ``--set``, by :func:`stages.profile`) under ``torch.profiler``, then the operations that
took the most of the CPU's own time, and every convolution shape, forward and backward, in
milliseconds per step with its share of all the profiled time. Reading the images, the robust
initialisation and the read-out are in the profile too (a few per cent of a short fit); the
per-step figures divide by the steps alone.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from torch.profiler import ProfilerActivity, profile

sys.path.insert(0, str(Path(__file__).resolve().parent))
import stages  # noqa: E402  (this folder's stage profiler)

CONVOLUTIONS = {"aten::mkldnn_convolution": "forward", "aten::_slow_conv2d_forward": "forward",
                "aten::convolution_backward": "backward"}


def convolution_rows(events, steps: int) -> list[tuple[str, str, float, float]]:
    """Per convolution shape and pass: (shape, pass, ms per step, share of all the self time).

    Args:
        events: ``torch.profiler``'s ``key_averages(group_by_input_shape=True)`` (each with
            ``key``, ``input_shapes`` and ``self_cpu_time_total`` in µs).
        steps: the fit's steps, which the times are divided by.

    Returns:
        Rows sorted by time, largest first; the shape reads ``in (B, C, H, W) → C_out, k×k``.

    Example:
        >>> from types import SimpleNamespace as E
        >>> rows = convolution_rows([E(key="aten::mkldnn_convolution", self_cpu_time_total=900.0,
        ...                            input_shapes=[[16, 16, 75, 75], [16, 16, 3, 3], [16]]),
        ...                          E(key="aten::add", self_cpu_time_total=100.0, input_shapes=[])], 10)
        >>> rows
        [('in (16, 16, 75, 75) → 16, 3×3', 'forward', 0.09, 0.9)]
    """
    total = sum(e.self_cpu_time_total for e in events) or 1.0
    rows = []
    for e in events:
        if e.key not in CONVOLUTIONS:
            continue
        shapes = [s for s in e.input_shapes if s]
        if e.key == "aten::convolution_backward":   # (grad_out, input, weight, ...)
            data, weight = shapes[1], shapes[2]
        else:                                       # (input, weight, bias, ...)
            data, weight = shapes[0], shapes[1]
        shape = f"in {tuple(data)} → {weight[0]}, {weight[2]}×{weight[3]}"
        rows.append((shape, CONVOLUTIONS[e.key], e.self_cpu_time_total / 1000 / steps,
                     e.self_cpu_time_total / total))
    return sorted(rows, key=lambda row: -row[2])


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--subject", default="ball")
    parser.add_argument("--steps", type=int, default=80)
    parser.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE")
    parser.add_argument("--out", type=Path, default=Path("runs/speed-ops"))
    parser.add_argument("--diligent", type=Path, default=stages.DILIGENT)
    parser.add_argument("--rows", type=int, default=15, help="operations listed (default 15)")
    args = parser.parse_args(argv)
    if args.steps < 2:
        parser.error(f"--steps must be at least 2, got {args.steps}")
    logging.basicConfig(level=logging.WARNING)
    overrides = [f"preset.steps={args.steps}", f"preset.lr_drop_at={args.steps - 1}", *args.set]
    with profile(activities=[ProfilerActivity.CPU], record_shapes=True) as prof:
        result = stages.profile(args.subject, overrides, args.out, args.diligent)
    steps = result["steps"]
    step_ms = 1000 * result["seconds"].get("steps", 0.0) / max(steps, 1)
    print(f"machine: {stages.machine()}")
    print(f"{args.subject}: method=unps preset=fast light=gt {' '.join(overrides)}; "
          f"{steps} steps at {step_ms:.0f} ms a step, working grid "
          f"{'×'.join(map(str, result['grid'][::-1])) if result['grid'] else '–'}\n")
    print(prof.key_averages().table(sort_by="self_cpu_time_total", row_limit=args.rows))
    print(f"\n{'convolution':<40}{'pass':>10}{'ms/step':>10}{'share':>8}")
    for shape, kind, ms, share in convolution_rows(prof.key_averages(group_by_input_shape=True), steps):
        print(f"{shape:<40}{kind:>10}{ms:>10.1f}{100 * share:>7.1f}%")


if __name__ == "__main__":
    main()

"""Average light-network weights: one network whose every parameter is the mean of several runs'.

    python experiments/light_estimation/average_weights.py OUT.pt RUN_P.pt RUN_R.pt
    python experiments/light_estimation/average_weights.py OUT.pt A.pt B.pt --shares 0.7 0.3

The inputs are exported weights (``python -m unps.lightnet.export``) of the same architecture,
usually fine-tunes of one parent ("model soups", Wortsman et al., ICML 2022). The mean is taken in
float32 and stored in the first file's precision; the config is the first file's, and the notes
say what was averaged. Read the result as any weights: ``benchmark.py --set checkpoint=OUT.pt``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import torch

from unps.io.files import atomic_path


def average_state(states: list[dict[str, torch.Tensor]], shares: list[float]) -> dict[str, torch.Tensor]:
    """Σ share_k · state_k, parameter by parameter, in float32, cast back to the first state's dtypes.

    Raises:
        ValueError: the states do not hold the same parameters with the same shapes, or the shares
            are not as many as the states, positive and summing to 1.
    """
    if len(shares) != len(states) or min(shares) <= 0 or abs(sum(shares) - 1) > 1e-6:
        raise ValueError(f"shares must be {len(states)} positive numbers summing to 1, got {shares}")
    first = states[0]
    for k, state in enumerate(states[1:], 1):
        if state.keys() != first.keys() or any(state[n].shape != first[n].shape for n in first):
            raise ValueError(f"weights {k + 1} do not have the parameters of weights 1")
    return {name: sum(share * state[name].float() for share, state in zip(shares, states))
            .to(first[name].dtype) for name in first}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("weights", type=Path, nargs="+", help="exported weights (.pt)")
    parser.add_argument("--shares", type=float, nargs="+", default=None, help="default: equal")
    args = parser.parse_args()
    if len(args.weights) < 2:
        parser.error("give at least two weights to average")
    missing = [str(w) for w in args.weights if not w.is_file()]
    if missing:
        parser.error(f"no such weights: {' '.join(missing)}")
    shares = args.shares or [1 / len(args.weights)] * len(args.weights)
    files = [torch.load(w, map_location="cpu", weights_only=False) for w in args.weights]
    try:
        state = average_state([f["state_dict"] for f in files], shares)
    except ValueError as e:
        parser.error(str(e))
    notes = {"averaged": [str(w) for w in args.weights], "shares": shares,
             "notes": [f.get("notes", {}) for f in files]}
    with atomic_path(args.out) as tmp:
        torch.save({**files[0], "state_dict": state, "notes": notes}, tmp)
    print(f"{args.out}: {' + '.join(f'{s:.2f}·{w.name}' for s, w in zip(shares, args.weights))}")


if __name__ == "__main__":
    main()

"""``python -m unps.lightnet.export RUN_FOLDER``: ship a training run's weights with unps.

Writes ``unps/lightnet/weights/lightnet.pt`` (or ``--out``): the network in float16, the run's
config, and notes read from the run itself (its command, steps, training time and final
validation metrics), so the shipped file says how it was made.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import yaml

from unps.lightnet.system import SHIPPED, export_weights


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("run", type=Path, help="an unps.train run folder")
    parser.add_argument("--checkpoint", default="last.ckpt", help="file in <run>/checkpoints")
    parser.add_argument("--out", type=Path, default=SHIPPED)
    args = parser.parse_args()

    metrics = json.loads((args.run / "metrics.json").read_text())
    overrides = yaml.safe_load((args.run / ".hydra" / "overrides.yaml").read_text()) or []
    notes = {"command": " ".join(["python -m unps.train", *overrides]),
             "checkpoint": args.checkpoint, "steps": metrics["steps"],
             "train_seconds": round(metrics["train_seconds"]),
             "val_direction_mae": round(metrics["val/direction_mae"], 3),
             "val_intensity_error": round(metrics["val/intensity_error"], 4)}
    out = export_weights(args.run / "checkpoints" / args.checkpoint, args.out, notes)
    print(f"{out}: {out.stat().st_size / 1e6:.1f} MB; {notes}")


if __name__ == "__main__":
    main()

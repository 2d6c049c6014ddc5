"""From a configuration to a finished run folder: what ``python -m unps.fit`` runs."""

from unps.pipeline.run import fit

__all__ = ["fit"]

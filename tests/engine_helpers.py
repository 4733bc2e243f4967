"""The tiny study the engine tests share (test_engine.py, test_compact.py) and how they
read a folder's run tables."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import yaml

TINY = {
    "name": "tiny",
    "seed": 0,
    "personas": {"source": "synthetic", "n": 300},
    "matched_n": 40,
    "mappings": ["A"],
    "parts": {
        "main": {
            "populations": ["mixed", "matched_base", "matched_deadline"],
            "controllers": ["robot_orca", "reactive"],
            "episodes": {
                "scenes": ["sidewalk", "head_on", "bottleneck"],
                "widths": [1.8, 3.0],
                "densities": [0.06],
                "robot_speeds": [1.0],
                "variants": [1],
            },
        }
    },
}


def tables(folder: Path) -> tuple[pd.DataFrame, pd.DataFrame]:
    return pd.read_parquet(folder / "runs.parquet"), pd.read_parquet(folder / "pedestrians.parquet")


def with_controllers(*controllers: str) -> dict:
    """:data:`TINY` running ``controllers`` only."""
    study = yaml.safe_load(yaml.safe_dump(TINY))
    study["parts"]["main"]["controllers"] = list(controllers)
    return study

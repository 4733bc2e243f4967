"""The populations table as the pipeline builds it, for tests that start from profiles."""

from __future__ import annotations

from collections.abc import Sequence

import pandas as pd

from popnavshift.populations.build import attach_profiles, membership


def build_populations(
    personas: pd.DataFrame,
    responses: pd.DataFrame,
    profiles_a: pd.DataFrame,
    matched: Sequence[str],
    profiles: pd.DataFrame | None = None,
) -> pd.DataFrame:
    """Membership from Mapping A, parameters from ``profiles`` (default: Mapping A)."""
    members = membership(personas, responses, profiles_a, matched)
    return attach_profiles(members, profiles_a if profiles is None else profiles)

"""Null populations: the study's design with the population effect removed.

A reversal rate means little on its own: controller differences within a cell are
noisy, so two populations reverse some rankings even when they do not differ at
all. A *null population* is built so that the observed comparison and its null
are computed at the same design (same episodes, slots, controllers and
backends); the analysis (:mod:`popnavshift.analysis.nulls`) reports every
headline rate as its excess over its null. Nulls are ordinary populations: they
are declared in the study file, planned, cached and resumed like any other run.

* **Swap null of the matched pair** (``matched_swap<k>_a`` / ``_b``, k = 1 … P):
  the same persona ids as ``matched_base``/``matched_deadline`` (so the same
  persona in every slot), and each persona's base and deadline profiles are
  assigned to the two arms by a seeded fair coin: arm ``a`` takes the deadline
  profile where the coin is 1, arm ``b`` the other one. The arms differ by exactly
  as much as the matched pair does, persona by persona, but in no systematic
  direction.
* **Size-matched null** (``<population>_sized<k>``): a seeded random subset of
  ``mixed`` (baseline profiles) with as many members as ``<population>``; the
  null of a cohort pair (P, Q) is (P_sized<k>, Q_sized<k>). ``mixed`` is its own
  size-matched subset, so it has no sized population.
* **Split halves** (``<population>_half_a`` / ``_half_b``, in :mod:`.build`) stay
  the persona-sampling diagnostic of the noise floor.

Each is a :class:`popnavshift.populations.identity.PopulationSpec`, the one home of
these names; each kind is declared, with these draws, in
:data:`popnavshift.populations.identity.NULL_KINDS`. This module holds the seeded draws.
"""

from __future__ import annotations

import numpy as np


def swap_variants(ids: list[str], arm: str, rng: np.random.Generator) -> list[str]:
    """Each of ``ids`` (sorted persona ids of the matched pair) → ``"deadline"`` or
    ``"baseline"`` in one arm of a swap permutation.

    One fair coin per persona, drawn from ``rng`` (seeded by the permutation: both arms
    draw the same coins) in id order: arm ``a`` takes the deadline profile where the coin
    is 1, arm ``b`` where it is 0, so the two arms are complementary.
    """
    coins = rng.integers(0, 2, size=len(ids)).astype(bool)
    deadline = coins if arm == "a" else ~coins
    return ["deadline" if d else "baseline" for d in deadline]


def sized_subset(source_ids: list[str], size: int, rng: np.random.Generator) -> list[str]:
    """A random subset (without replacement) of ``size`` of ``source_ids``, sorted, drawn
    from ``rng`` (seeded by the population it stands in for and the replicate, so the
    subsets of two cohorts of one replicate are independent)."""
    ids = np.sort(np.asarray(source_ids, dtype=str))
    take = min(int(size), len(ids))
    return sorted(ids[rng.choice(len(ids), size=take, replace=False)].tolist())

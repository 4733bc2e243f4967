"""One colour and one marker per controller, the same on every card, compare page and
report figure; and its name on a page (:func:`controller_label`).

The paper's controllers (and the report's ``pooled`` line) have fixed styles; any other
name gets a colour and a marker from a stable hash of the name (sha256, the same in every
process and on every machine), never from its position in a list. Alone
(:func:`controller_style`) two names can draw the same pair; in a figure or leaderboard of
several (:func:`controller_styles`) no two share a colour or a marker while the palette
lasts: a name whose hashed colour (or marker) another already holds takes the next free
one, in the order of the names' hashes, so the result does not depend on the order the
names are given in.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

from ..controller_ids import display_name
from ..hashing import digest
from ..paper import CONTROLLERS
from ..tables import NO_ROBOT, NO_ROBOT_LABEL

#: the label of each of the paper's controllers (declared with them) and of the no-robot runs
LABELS: dict[str, str] = {**{c.name: c.label for c in CONTROLLERS}, NO_ROBOT: NO_ROBOT_LABEL}


class Style(NamedTuple):
    """A controller's matplotlib colour (lower-case hex, as ``to_hex`` gives) and marker."""

    colour: str
    marker: str


FIXED: dict[str, Style] = {
    "reactive": Style("#4c72b0", "o"),
    "early_yield": Style("#dd8452", "s"),
    "robot_orca": Style("#55a868", "^"),
    "pooled": Style("#222222", "D"),
}
#: colours and markers of any other controller: none of them is a fixed style's colour
PALETTE: tuple[str, ...] = ("#c44e52", "#8172b3", "#937860", "#e7298a", "#8c8c00", "#17becf",
                            "#2f4f4f", "#b8860b", "#1f3b73", "#7f7f7f", "#7f3f00")
MARKERS: tuple[str, ...] = ("v", "P", "X", "h", "<", ">", "p", "*", "d", "8", "H")


def controller_style(name: str) -> Style:
    """The style of controller ``name``: fixed for the paper's controllers, else chosen by
    a stable hash of the name (module doc)."""
    if name in FIXED:
        return FIXED[name]
    h = _hash(name)
    return Style(PALETTE[h % len(PALETTE)], MARKERS[(h // len(PALETTE)) % len(MARKERS)])



def controller_label(name: str) -> str:
    """How a page names controller ``name``: the paper's name for one of its controllers
    (:data:`popnavshift.paper.CONTROLLERS`), ``no robot`` for the baselines, a policy file's
    name and hash for a learned policy (:func:`popnavshift.controller_ids.policy_label`),
    else its id."""
    return LABELS.get(name) or display_name(name)


def _hash(name: str) -> int:
    return int(digest(["controller-style", name])[:12], 16)


def controller_styles(names: Sequence[str]) -> dict[str, Style]:
    """A style for each of ``names``, no two alike (module doc): the paper's fixed ones, then
    the others in the order of their hashes, each its hashed colour and marker unless
    taken, else the next free one (colours and markers are reused only when every one is
    taken)."""
    out = {n: FIXED[n] for n in names if n in FIXED}
    colours = {s.colour for s in out.values()}
    markers = {s.marker for s in out.values()}
    for name in sorted((n for n in dict.fromkeys(names) if n not in FIXED), key=_hash):
        h = _hash(name)
        colour = _free(PALETTE, h % len(PALETTE), colours)
        marker = _free(MARKERS, (h // len(PALETTE)) % len(MARKERS), markers)
        colours.add(colour)
        markers.add(marker)
        out[name] = Style(colour, marker)
    return {n: out[n] for n in names}


def _free(options: Sequence[str], start: int, taken: set[str]) -> str:
    """The first of ``options`` from ``start`` on (cyclically) not in ``taken``; ``start``'s
    own when every one is taken."""
    for i in range(len(options)):
        candidate = options[(start + i) % len(options)]
        if candidate not in taken:
            return candidate
    return options[start]

"""One colour and one marker per controller, the same on every card, compare page and
report figure; and its name on a page (:func:`controller_label`).

The paper's controllers (and the report's ``pooled`` line) have fixed styles; any other
name gets a colour and a marker from a stable hash of the name (sha256, the same in every
process and on every machine), never from its position in a list, so a controller looks
the same whichever other controllers share the figure. Two unknown names can draw the
same pair (7 colours × 6 markers); the legend still tells them apart.
"""

from __future__ import annotations

from typing import NamedTuple

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
PALETTE: tuple[str, ...] = ("#c44e52", "#8172b3", "#937860", "#da8bc3", "#ccb974", "#64b5cd",
                            "#2f4f4f")
MARKERS: tuple[str, ...] = ("v", "P", "X", "h", "<", ">")


def controller_style(name: str) -> Style:
    """The style of controller ``name``: fixed for the paper's controllers, else chosen by
    a stable hash of the name (module doc)."""
    if name in FIXED:
        return FIXED[name]
    h = int(digest(["controller-style", name])[:12], 16)
    return Style(PALETTE[h % len(PALETTE)], MARKERS[(h // len(PALETTE)) % len(MARKERS)])



def controller_label(name: str) -> str:
    """How a page names controller ``name``: the paper's name for one of its controllers
    (:data:`popnavshift.paper.CONTROLLERS`), ``no robot`` for the baselines, else its id."""
    return LABELS.get(name, name)

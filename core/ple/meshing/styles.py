"""The registry of tessellation styles: one list that the CLI, batch jobs, the add-on and the
exporters read (names, labels, what each makes); the triangles each makes are estimated by
``model.budget.mesh_triangles``."""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import PleError, echo

DEFAULT_LEVELS = 4
DEFAULT_SEGMENTS = 16


@dataclass(frozen=True)
class Style:
    """A tessellation style: ``name`` on the command line, ``label`` in the add-on, ``solid``
    True when it makes a closed, oriented solid (False: a preview)."""

    name: str
    label: str
    description: str
    solid: bool


STYLES = {s.name: s for s in (
    Style("refined", "Refined", "CNT refined towards the exact hub surfaces (CHoCC paper §6)", True),
    Style("cnt", "CNT", "convex-hull network tessellation: one triangle per CHoCC triangle, flat corridors", True),
    Style("chocc", "CHoCC", "convex hulls of cospherical circles per hub, sampled corridors (CHoCC paper)", True),
    Style("balls-beams", "Balls and beams (preview)",
          "preview: an icosphere per ball, a frustum per beam (not a closed solid)", False),
)}
STYLE_NAMES = tuple(STYLES)
DEFAULT_STYLE = "refined"


def style(name: str) -> Style:
    """The style called ``name``; an unknown name is a user error listing the styles."""
    if name not in STYLES:
        raise PleError(f"style {echo(name)}: expected one of {', '.join(STYLE_NAMES)}")
    return STYLES[name]

"""The registry of tessellation styles: one list that the CLI, batch jobs, the add-on and the
exporters read (names, labels, what each makes, about how many triangles)."""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import PleError
from ..model.lattice import Lattice
from ..model.work import Estimate, estimate


@dataclass(frozen=True)
class Style:
    """A tessellation style: ``name`` on the command line, ``label`` in the add-on, ``solid``
    True when it makes a closed, oriented solid (False: a preview). ``per_beam_end`` and
    ``per_ball`` are the triangles it makes, about, per beam end and per ball (bare caps,
    icospheres); a refined style multiplies ``per_beam_end`` by 4 per level."""

    name: str
    label: str
    description: str
    solid: bool
    per_beam_end: float = 0.0
    per_ball: float = 0.0
    refined: bool = False

    def triangles(self, balls: int, beams: int, levels: int = 4) -> int:
        """About how many triangles this style makes of ``balls`` balls and ``beams`` beams."""
        per_end = self.per_beam_end * (4.0 ** levels if self.refined else 1.0)
        return int(2 * beams * per_end + balls * self.per_ball)


# triangles per beam end (measured on cubic, octet and fig6_3 3³ regions: chocc 41-53, cnt 12-17,
# refined at 4 levels 1825-2521 = about 8-10 x 4**levels) and per ball
STYLES = {s.name: s for s in (
    Style("refined", "Refined", "CNT refined towards the exact hub surfaces (CHoCC paper §6)", True,
          10.0, 24.0, refined=True),
    Style("cnt", "CNT", "convex-hull network tessellation: one triangle per CHoCC triangle, flat corridors", True,
          18.0, 24.0),
    Style("chocc", "CHoCC", "convex hulls of cospherical circles per hub, sampled corridors (CHoCC paper)", True,
          55.0, 24.0),
    Style("balls-beams", "Balls and beams (preview)",
          "preview: an icosphere per ball, a frustum per beam (not a closed solid)", False, 8.0, 80.0),
)}
STYLE_NAMES = tuple(STYLES)
DEFAULT_STYLE = "refined"


def style(name: str) -> Style:
    """The style called ``name``; an unknown name is a user error listing the styles."""
    if name not in STYLES:
        raise PleError(f"style {name!r}: expected one of {', '.join(STYLE_NAMES)}")
    return STYLES[name]


def mesh_estimate(lat: Lattice, region=None, name: str | None = None, levels: int = 4) -> Estimate:
    """``model.work.estimate`` of a region with the triangles of style ``name`` (none if None)
    counted: the work of tessellating it, before evaluating anything."""
    est = estimate(lat, region)
    if name is None:
        return est
    return est.with_triangles(style(name).triangles(est.balls, est.beams, levels))

"""What a CLG is (thesis §5.2–5.4, §10.1): primitives of the template group, compound primitives,
Boolean expressions, named template chunks, the solid over chunk unions, and materials.

A node is referenced as ``(di, dj, dk, n)`` relative to the chunk's group: in the copy of a
chunk at group (i, j, k) it is node N[i+di, j+dj, k+dk, n] of the pattern, which exists for all
integer indices through the powers of U, V, W, whether or not they commute (thesis §5.2;
``ple.clg.steady``). ``Ball(node, s)`` has the node's centre and s times its radius;
``Beam(a, b, (s1, s2))`` is the convex hull of two such balls. A chunk union is
the copy of a template chunk at every group of the pattern's count range; the solid is a Boolean
expression of chunk unions. A primitive with a material whose ``replace`` is a CLG L becomes
X ∩ L (§10.1), L placed in the world frame or in the primitive's beam frame.

Expressions are immutable trees: ``Prim`` leaves, ``Op`` nodes (union, intersection,
difference) and, in the solid, ``ChunkRef`` leaves. Compound primitives are expanded into
primitives and operators when the CLG is built (extended hubs need the pattern's beams).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from ..errors import PleError, echo
from ..model.lattice import MAX_COUNT, Lattice
from .field import FieldSolid

MAX_DEPTH = 8  # recursive CLG nesting limit (§10.1: infinite recursions must not be defined)
MAX_SCALE = 1e6  # a primitive at most 10⁶ times its node's radius: squares of radii stay finite
OPS = ("union", "intersection", "difference")
FRAMES = ("world", "beam")


@dataclass(frozen=True)
class NodeRef:
    """Node N[g + (di, dj, dk), n] of the copy at group g."""

    di: int
    dj: int
    dk: int
    n: int

    @property
    def offset(self) -> tuple[int, int, int]:
        return (self.di, self.dj, self.dk)


@dataclass(frozen=True)
class Prim:
    """A ball (``b`` is None) or a cone-beam primitive, with scales and an optional material."""

    a: NodeRef
    sa: float
    b: NodeRef | None = None
    sb: float = 0.0
    material: str | None = None

    @property
    def kind(self) -> str:
        return "ball" if self.b is None else "beam"


@dataclass(frozen=True)
class Op:
    kind: str
    args: tuple

    def __post_init__(self):
        if self.kind not in OPS:
            raise PleError(f"unknown operator {echo(self.kind)} (expected {', '.join(OPS)})")
        if not self.args:
            raise PleError(f"{self.kind}: needs at least one operand")


@dataclass(frozen=True)
class ChunkRef:
    name: str


@dataclass(frozen=True)
class Compound:
    """A compound primitive before expansion: hollow_beam, extended_hub or connector (§5.4)."""

    kind: str
    params: tuple
    material: str | None = None


@dataclass
class Material:
    """An abstract material (§10.1): ``replace`` is a CLG, a ``FieldSolid`` (a fitted field's
    {Φ ≤ level}, ``ple.clg.field``), a function of the template primitive returning either or
    None, or None (a plain material, e.g. a colour); ``frame`` says where L lives: "world", or
    "beam" (origin → first centre, (1, 0, 0) → second centre; a ball: its centre and radius)."""

    replace: object = None
    frame: str = "world"

    def __post_init__(self):
        if self.frame not in FRAMES:
            raise PleError(f"frame: expected world or beam, got {echo(self.frame)}")


# ----- building expressions (the Python API of programs) --------------------------------------------
def scale_value(s, where: str) -> float:
    if isinstance(s, bool) or not isinstance(s, (int, float)) or not math.isfinite(float(s)):
        raise PleError(f"{where}: expected a number, got {echo(s)}")
    if s <= 0:
        raise PleError(f"{where}: must be > 0, got {echo(s)}")
    if s > MAX_SCALE:
        raise PleError(f"{where}: {echo(s)} is beyond the largest scale {MAX_SCALE:g} of a node's radius")
    return float(s)


def scale_pair(s, where: str) -> tuple[float, float]:
    if isinstance(s, (int, float)) and not isinstance(s, bool):
        s = (s, s)
    if not isinstance(s, (list, tuple)) or len(s) != 2:
        raise PleError(f"{where}: expected two scales [s1, s2], got {echo(s)}")
    return scale_value(s[0], f"{where}[0]"), scale_value(s[1], f"{where}[1]")


def _ref(node, where: str):
    """Normalize a node reference: n (int or name) or (di, dj, dk, n); names resolved later."""
    if isinstance(node, NodeRef):
        return node
    if isinstance(node, (list, tuple)):
        if len(node) != 4:
            raise PleError(f"{where}: expected [di, dj, dk, n], got {echo(list(node))}")
        for x, name in zip(node[:3], ("di", "dj", "dk")):
            if isinstance(x, bool) or not isinstance(x, int):
                raise PleError(f"{where}: {name} must be an integer, got {echo(x)}")
        return (int(node[0]), int(node[1]), int(node[2]), node[3])
    return (0, 0, 0, node)


def Ball(node, scale: float = 1.0, material=None) -> Prim:
    """Ball(node, s): the node's centre, s times its radius."""
    return Prim(_ref(node, "ball.node"), scale_value(scale, "ball.scale"), None, 0.0, material)


def Beam(a, b, scale=(1.0, 1.0), material=None) -> Prim:
    """Beam(a, b, (s1, s2)): the convex hull of Ball(a, s1) and Ball(b, s2)."""
    s1, s2 = scale_pair(scale, "beam.scale")
    return Prim(_ref(a, "beam.from"), s1, _ref(b, "beam.to"), s2, material)


def HollowBeam(a, b, scale=(1.0, 1.0), hollow: float = 0.5, material=None) -> Compound:
    """Beam(s1, s2) − Beam(h s1, h s2), h ∈ (0, 1) (§5.4)."""
    s1, s2 = scale_pair(scale, "hollow_beam.scale")
    h = scale_value(hollow, "hollow_beam.hollow")
    if not 0 < h < 1:
        raise PleError(f"hollow_beam.hollow: must be in (0, 1), got {echo(hollow)}")
    return Compound("hollow_beam", (_ref(a, "hollow_beam.from"), _ref(b, "hollow_beam.to"), s1, s2, h), material)


def ExtendedHub(node, scale=(1.0, 1.0), material=None) -> Compound:
    """The union of the whole beams incident on a node (§5.4.1): s1 at the node, s2 at the other end."""
    s1, s2 = scale_pair(scale, "extended_hub.scale")
    return Compound("extended_hub", (_ref(node, "extended_hub.node"), s1, s2), material)


def Connector(node, outer: float, inner: float, reach: float, material=None) -> Compound:
    """Ball(node, reach) ∩ ExtendedHub(outer) − ExtendedHub(inner) (§5.4.2)."""
    s1, s2 = scale_value(outer, "connector.outer"), scale_value(inner, "connector.inner")
    r = scale_value(reach, "connector.reach")
    if s2 >= s1:
        raise PleError(f"connector.inner: must be smaller than outer ({s1}), got {s2}")
    return Compound("connector", (_ref(node, "connector.node"), s1, s2, r), material)


def Union(*args) -> Op:
    return Op("union", tuple(args))


def Intersection(*args) -> Op:
    return Op("intersection", tuple(args))


def Difference(first, *minus) -> Op:
    return Op("difference", (first, *minus))


def Chunk(name: str) -> ChunkRef:
    return ChunkRef(str(name))


# ----- the CLG ----------------------------------------------------------------------------------------
@dataclass
class CLG:
    """A (possibly recursive) CLG: pattern, named template chunks, solid, materials.

    Build with ``CLG(pattern, chunks={name: expr}, solid=expr, materials={id: Material})``;
    the constructor resolves node names, expands compound primitives and validates everything
    (unknown chunk, node, material, operator; nesting deeper than 8; scales ≤ 0)."""

    pattern: Lattice
    chunks: dict
    solid: object
    materials: dict = field(default_factory=dict)
    description: str = ""

    def __post_init__(self):
        if not isinstance(self.pattern, Lattice):
            raise PleError(f"pattern: expected a Lattice, got {type(self.pattern).__name__}")
        self.pattern.validate()
        if not isinstance(self.chunks, dict) or not self.chunks:
            raise PleError("chunks: expected at least one named chunk")
        mats = {}
        for mid, mat in (self.materials or {}).items():
            if not isinstance(mat, Material):
                raise PleError(f"materials.{mid}: expected a Material, got {type(mat).__name__}")
            if isinstance(mat.replace, CLG) and mat.replace.depth >= MAX_DEPTH:
                raise PleError(f"materials.{mid}.replace: nesting deeper than {MAX_DEPTH} levels")
            if mat.replace is not None and not isinstance(mat.replace, (CLG, FieldSolid)) \
                    and not callable(mat.replace):
                raise PleError(f"materials.{mid}.replace: expected a CLG, a FieldSolid or a function of the primitive")
            mats[str(mid)] = mat
        self.materials = mats
        self.chunks = {str(k): expand(v, self.pattern, f"chunks.{k}", set(mats)) for k, v in self.chunks.items()}
        self.solid = _check_solid(self.solid, set(self.chunks), "solid")
        self.replacements = {}  # template primitive -> (CLG, frame), from the materials
        for name, expr in self.chunks.items():
            for prim in leaves(expr):
                self._replacement(prim, f"chunks.{name}")

    def _replacement(self, prim: Prim, where: str):
        if prim.material is None or prim in self.replacements:
            return
        mat = self.materials[prim.material]
        rep = mat.replace
        if callable(rep) and not isinstance(rep, CLG):
            rep = rep(prim)  # R(X) (§10.1), once per template primitive
            if rep is not None and not isinstance(rep, (CLG, FieldSolid)):
                raise PleError(f"{where}: material {echo(prim.material)} returned {type(rep).__name__}, "
                               f"not a CLG or a FieldSolid")
            if rep is not None and rep.depth >= MAX_DEPTH:
                raise PleError(f"materials.{prim.material}.replace: nesting deeper than {MAX_DEPTH} levels")
        self.replacements[prim] = None if rep is None else (rep, mat.frame)

    @property
    def depth(self) -> int:
        """1 for a plain CLG, 1 + the deepest replacement otherwise."""
        subs = [m.replace.depth for m in self.materials.values() if isinstance(m.replace, CLG)]
        subs += [r[0].depth for r in getattr(self, "replacements", {}).values() if r is not None]
        return 1 + max(subs, default=0)

    def primitive_count(self) -> int:
        return sum(len(leaves(e)) for e in self.chunks.values())

    def with_pattern(self, pattern: Lattice) -> CLG:
        """The same chunks, solid and materials on another pattern (e.g. one whose frames were edited)."""
        return CLG(pattern, self.chunks, self.solid, self.materials, self.description)

    def showing(self, chunk: str | None) -> CLG:
        """The CLG whose solid is one chunk union (None: this CLG)."""
        if chunk is None:
            return self
        if chunk not in self.chunks:
            raise PleError(f"unknown chunk {echo(chunk)} (chunks: {', '.join(sorted(self.chunks))})")
        return CLG(self.pattern, self.chunks, ChunkRef(chunk), self.materials, self.description)

    def used_chunks(self) -> list[str]:
        return sorted({c.name for c in chunk_refs(self.solid)})


def _node(lat: Lattice, ref, where: str) -> NodeRef:
    di, dj, dk, n = (ref.di, ref.dj, ref.dk, ref.n) if isinstance(ref, NodeRef) else ref
    if isinstance(n, bool):
        raise PleError(f"{where}: unknown node {echo(n)}")
    for d, name in ((di, "di"), (dj, "dj"), (dk, "dk")):
        if not -MAX_COUNT <= d <= MAX_COUNT:  # as a beam's offset (ple.model.schema)
            raise PleError(f"{where}: {name} {d} is outside ±{MAX_COUNT:,}")
    try:
        return NodeRef(int(di), int(dj), int(dk), lat.node_id(n))
    except PleError:
        raise PleError(f"{where}: unknown node {echo(n)} (the pattern has {len(lat.nodes)} nodes)") from None


def expand(expr, lat: Lattice, where: str, materials: set):
    """Resolve node references and expand compound primitives into Prim/Op trees."""
    if isinstance(expr, Prim):
        if expr.material is not None and str(expr.material) not in materials:
            raise PleError(f"{where}.material: unknown material {echo(expr.material)}")
        mat = None if expr.material is None else str(expr.material)
        w = f"{where}.{expr.kind}"
        b = None if expr.b is None else _node(lat, expr.b, f"{w}.to")
        return Prim(_node(lat, expr.a, f"{w}.{'node' if b is None else 'from'}"), expr.sa, b, expr.sb, mat)
    if isinstance(expr, Op):
        return Op(expr.kind, tuple(expand(x, lat, f"{where}.{expr.kind}[{n}]", materials)
                                   for n, x in enumerate(expr.args)))
    if isinstance(expr, Compound):
        mat = expr.material
        if mat is not None and str(mat) not in materials:
            raise PleError(f"{where}.material: unknown material {echo(mat)}")
        return expand(_expand_compound(expr, lat, where), lat, where, materials)
    if isinstance(expr, ChunkRef):
        raise PleError(f"{where}: a chunk cannot use another chunk ({echo(expr.name)}); chunks are built of primitives")
    raise PleError(f"{where}: expected a primitive or an operator, got {type(expr).__name__}")


def _expand_compound(c: Compound, lat: Lattice, where: str):
    m = c.material
    if c.kind == "hollow_beam":
        a, b, s1, s2, h = c.params
        a, b = _node(lat, a, f"{where}.hollow_beam.from"), _node(lat, b, f"{where}.hollow_beam.to")
        return Op("difference", (Prim(a, s1, b, s2, m), Prim(a, h * s1, b, h * s2, m)))
    if c.kind == "extended_hub":
        node, s1, s2 = c.params
        return _hub(lat, _node(lat, node, f"{where}.extended_hub.node"), s1, s2, m, where)
    if c.kind == "connector":
        node, s1, s2, r = c.params
        ref = _node(lat, node, f"{where}.connector.node")
        return Op("difference", (Op("intersection", (Prim(ref, r, None, 0.0, m), _hub(lat, ref, s1, s1, m, where))),
                                 _hub(lat, ref, s2, s2, m, where)))
    raise PleError(f"{where}: unknown compound primitive {echo(c.kind)}")


def _hub(lat: Lattice, node: NodeRef, s1: float, s2: float, m, where: str) -> Op:
    """Every beam incident on ``node``, from the pattern's beam-patterns, whole (§5.4.1)."""
    beams = []
    for bp in lat.beams:
        if bp.n1 == node.n:  # node is the from-end: the other end is at +offset
            other = NodeRef(node.di + bp.di, node.dj + bp.dj, node.dk + bp.dk, bp.n2)
            beams.append(Prim(node, s1, other, s2, m))
        if bp.n2 == node.n:  # node is the to-end: the other end is at −offset
            other = NodeRef(node.di - bp.di, node.dj - bp.dj, node.dk - bp.dk, bp.n1)
            beams.append(Prim(node, s1, other, s2, m))
    if not beams:
        raise PleError(f"{where}: node {node.n} has no incident beam-patterns (an extended hub needs beams)")
    return Op("union", tuple(beams))


def _check_solid(expr, names: set, where: str):
    if isinstance(expr, str):
        expr = ChunkRef(expr)
    if isinstance(expr, ChunkRef):
        if expr.name not in names:
            raise PleError(f"{where}: unknown chunk {echo(expr.name)} (chunks: {', '.join(sorted(names))})")
        return expr
    if isinstance(expr, Op):
        return Op(expr.kind, tuple(_check_solid(x, names, f"{where}.{expr.kind}[{n}]")
                                   for n, x in enumerate(expr.args)))
    raise PleError(f"{where}: expected a chunk name or an operator over chunk names, got {type(expr).__name__}")


def leaves(expr) -> list:
    """The leaves (Prim or ChunkRef) of an expression, left to right."""
    if isinstance(expr, Op):
        return [x for a in expr.args for x in leaves(a)]
    return [expr]


def chunk_refs(expr) -> list[ChunkRef]:
    return [x for x in leaves(expr) if isinstance(x, ChunkRef)]


def positive_leaves(expr) -> list:
    """Leaves whose union bounds the expression: a union needs all its operands, an intersection
    only its first, a difference only what it subtracts from."""
    if isinstance(expr, Op):
        if expr.kind == "union":
            return [x for a in expr.args for x in positive_leaves(a)]
        return positive_leaves(expr.args[0])
    return [expr]


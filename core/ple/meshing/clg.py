"""Meshes of CLG solids (thesis §5): each template chunk is meshed once (balls and cone-beams as
polyhedra, combined by its Boolean expression), its copies are placed by the similarity
``M_g ∘ G⁻¹`` of each group (on patterns whose U, V, W do not commute, each copy is meshed from
the lattice's own nodes instead, ``ple.clg.steady``), and chunk unions and the solid are
combined by manifold3d's robust booleans, whose output is watertight and free of
self-intersections by construction. A primitive with a replacing CLG becomes X ∩ mesh(L), L
placed by its material's frame (§10.1).

Polyhedra are scaled about their centres so that a meshed ball has the ball's exact volume (an
inscribed polyhedron would lose ~1 % at 32 segments); beams are hulls of two such balls.
"""

from __future__ import annotations

import numpy as np

from ..clg.field import FieldSolid
from ..clg.model import CLG, Prim
from ..clg.query import compiled, frame_of
from ..errors import PleError, echo
from ..model.budget import CLG_TRIANGLE_BYTES, require, sphere_triangles
from .unions import unit_ball

MAX_TRIANGLES = 20_000_000  # estimated output size beyond which meshing is refused


def _manifold():
    try:
        import manifold3d
    except ImportError:
        raise PleError("CLG meshing needs manifold3d (pip install manifold3d)") from None
    return manifold3d


def _similarity_3x4(lin: np.ndarray, move: np.ndarray) -> np.ndarray:
    return np.column_stack([lin, move])


def _leaf(m, comp, prim: Prim, balls, unit, segments: int, solids: dict):
    """The manifold of one primitive from its balls (ca (3,), ra, cb (3,) or None, rb). ``solids``:
    the nested materials' solids meshed so far (id of their compiled CLG -> manifold), each
    meshed once and placed in every leaf that carries it."""
    ca, ra, cb, rb = balls
    ball_a = unit.scale([ra] * 3).translate(list(ca))
    if cb is None:
        x = ball_a
    else:
        x = m.Manifold.batch_hull([ball_a, unit.scale([rb] * 3).translate(list(cb))])
    child = comp.children.get(prim)
    if child is None:
        return x
    sub, frame = child
    if isinstance(sub, FieldSolid):  # an implicit surface, not a hull of balls
        raise PleError("a CLG whose material is a fitted field cannot be meshed by manifold3d; "
                       "use `ple clg voxels` (or slices, renders) instead")
    o, rot, f = frame_of(frame, ca[None], np.array([ra]), None if cb is None else cb[None])
    if id(sub) not in solids:
        solids[id(sub)] = _solid_manifold(m, sub, segments, solids)
    inner = solids[id(sub)].transform(_similarity_3x4(rot[0] * f[0], o[0]))
    return x ^ inner


def _expr(m, tree, parts):
    if isinstance(tree, int):
        return parts[tree]
    kind, args = tree
    vals = [_expr(m, a, parts) for a in args]
    if kind == "union":
        return m.Manifold.batch_boolean(vals, m.OpType.Add) if len(vals) > 1 else vals[0]
    if kind == "intersection":
        return m.Manifold.batch_boolean(vals, m.OpType.Intersect) if len(vals) > 1 else vals[0]
    return m.Manifold.batch_boolean(vals, m.OpType.Subtract) if len(vals) > 1 else vals[0]


def chunk_triangles(comp, ci: int, segments: int, nested: dict | None = None) -> float:
    """Triangles of chunk ``ci``'s template (one group), bounded from above before anything is
    meshed: a sphere per ball, two per beam (their hull), and each nested material's whole solid
    inside every leaf that carries one: its real triangles where ``nested`` (id of its compiled
    CLG -> triangles) has them, else its bound (``solid_triangles``)."""
    ball = sphere_triangles(segments)
    total = 0.0
    for prim in comp.leaves[ci]:
        total += ball if prim.b is None else 2 * ball
        child = comp.children.get(prim)
        if child is not None and not isinstance(child[0], FieldSolid):
            sub = child[0]
            total += nested[id(sub)] if nested is not None and id(sub) in nested else solid_triangles(sub, segments,
                                                                                                       nested)
    return total


def solid_triangles(comp, segments: int, nested: dict | None = None) -> float:
    """Triangles of a compiled CLG's solid, bounded from above from its leaves and groups alone
    (nested materials included, as ``chunk_triangles`` counts them): the budget's estimate,
    before any Boolean runs."""
    r = comp.region if comp.region is not None else comp.lat.region(None)
    return sum(chunk_triangles(comp, ci, segments, nested) for ci in range(len(comp.names))) * r.groups


def nested_materials(comp) -> list:
    """The compiled CLGs of ``comp``'s nested materials (meshable ones, each once), deepest first."""
    out: list = []
    for sub, _ in comp.children.values():
        if not isinstance(sub, FieldSolid) and all(sub is not x for x in out):
            out += [x for x in nested_materials(sub) if all(x is not y for y in out)] + [sub]
    return out


def check_budget(comp, segments: int, max_bytes: float | None = None, nested: dict | None = None,
                 counted: str = "nested materials included") -> None:
    """Refuse, before any Boolean, a CLG whose mesh would be too large: a chunk of more than
    ``MAX_TRIANGLES`` estimated triangles, or a solid needing more than ``max_bytes``; nested
    materials count as ``chunk_triangles`` counts them (``counted`` says how, in the message).
    PleError naming the estimate."""
    r = comp.region if comp.region is not None else comp.lat.region(None)
    groups = r.groups  # counted before the groups are listed: a huge pattern is refused first
    for ci in range(len(comp.names)):
        est = chunk_triangles(comp, ci, segments, nested) * groups
        if est > MAX_TRIANGLES:
            raise PleError(f"chunk {echo(comp.names[ci])}: about {est:.3g} triangles exceed the meshing limit "
                           f"{MAX_TRIANGLES:.0e}; use fewer groups or --segments")
    if max_bytes is not None:
        total = solid_triangles(comp, segments, nested)
        require(total * CLG_TRIANGLE_BYTES, f"{total:.3g} triangles of the CLG mesh ({groups:,} groups, {counted})",
                max_bytes, "use fewer groups or --segments")


def check_outer_budget(comp, segments: int, max_bytes: float | None = None) -> None:
    """``check_budget`` of the leaves alone, every nested material counted as empty: a lower
    bound, checked before anything is meshed (``mesh_arrays`` checks the rest as it goes)."""
    subs = nested_materials(comp)
    check_budget(comp, segments, max_bytes, {id(sub): 0 for sub in subs},
                 "nested materials not counted yet" if subs else "no nested materials")


def _solid_manifold(m, comp, segments: int, solids: dict):
    unit = unit_ball(m, segments)
    g = comp.groups()
    lin, move, _ = comp.copies(g) if comp.similar else (None, None, None)
    unions = []
    for ci in range(len(comp.names)):
        if comp.similar:  # one template chunk (group 0), placed by M_g ∘ G⁻¹ per copy
            parts = [_leaf(m, comp, prim, _group0(comp, prim), unit, segments, solids) for prim in comp.leaves[ci]]
            template = _expr(m, comp.trees[ci], parts)
            copies = [template.transform(_similarity_3x4(lin[n], move[n])) for n in range(len(g))]
        else:  # copies are not similar: each from the lattice's own nodes (ple.clg.steady)
            balls = comp.prim_balls(comp.leaves[ci], g)
            copies = [_expr(m, comp.trees[ci], [_leaf(m, comp, prim, _one(b, n), unit, segments, solids)
                                                 for prim, b in zip(comp.leaves[ci], balls)]) for n in range(len(g))]
        unions.append(m.Manifold.batch_boolean(copies, m.OpType.Add) if len(copies) > 1 else copies[0])
    return _expr(m, comp.solid, unions)


def _group0(comp, prim: Prim):
    """A primitive's balls in the group-0 copy (similar copies)."""
    (ca, cb), (ra, rb) = comp.balls0[prim]
    return ca, ra, cb, rb


def _one(balls, n: int):
    """Copy ``n`` of a primitive's balls (``Compiled.prim_balls``)."""
    ca, ra, cb, rb = balls
    return ca[n], float(ra[n]), None if cb is None else cb[n], None if cb is None else float(rb[n])


def mesh_clg(clg: CLG, segments: int = 32, region=None, max_bytes: float | None = None):
    """A watertight trimesh of the CLG solid (of the chunk copies at the groups of ``region``, a
    ``Region``, if given: the add-on's preview of its drawn region). Refused before meshing when
    its estimated triangles exceed ``MAX_TRIANGLES`` or need more than ``max_bytes``."""
    return mesh_compiled(compiled(clg, region), segments, max_bytes)


def mesh_compiled(comp, segments: int = 32, max_bytes: float | None = None):
    """``mesh_clg`` of a compiled CLG (``ple.clg.query.Compiled``, its copies placed as it places them)."""
    import trimesh
    return trimesh.Trimesh(*mesh_arrays(comp, segments, max_bytes), process=False)


def mesh_arrays(comp, segments: int = 32, max_bytes: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The CLG solid's mesh as arrays: vertices (V, 3) float64, faces (F, 3) int64 (what a child
    process sends back, ``ple.program.meshes.mesh_clg_contained``). Budgeted before any Boolean
    by its leaves (``check_outer_budget``), each nested material before it is meshed, and the
    whole solid with the nested materials' real triangles before the rest is meshed."""
    if segments < 8 or segments > 512:
        raise PleError(f"--segments {segments}: expected 8..512")
    m = _manifold()
    check_outer_budget(comp, segments, max_bytes)
    solids, nested = _nested_solids(m, comp, segments, max_bytes)
    if nested:
        check_budget(comp, segments, max_bytes, nested, "nested materials as meshed")
    out = _solid_manifold(m, comp, segments, solids).to_mesh()
    verts = np.asarray(out.vert_properties, float)[:, :3]
    faces = np.asarray(out.tri_verts, np.int64)
    if len(faces) == 0:
        raise PleError("the CLG solid is empty: nothing to mesh")
    return verts, faces


def _nested_solids(m, comp, segments: int, max_bytes: float | None) -> tuple[dict, dict]:
    """The nested materials' solids and triangles (ids of their compiled CLGs -> manifold, ->
    triangles), meshed deepest first, each refused by its own estimate before it is meshed: the
    solid is then estimated with their real triangles (their bounds are several times loose)."""
    solids: dict = {}
    nested: dict = {}
    for sub in nested_materials(comp):
        check_budget(sub, segments, max_bytes, nested)
        solids[id(sub)] = _solid_manifold(m, sub, segments, solids)
        nested[id(sub)] = solids[id(sub)].num_tri()
    return solids, nested


def estimated_triangles(comp, segments: int = 32) -> float:
    """The triangles ``mesh_arrays`` budgets the whole solid by before its Booleans: the leaves'
    bound, each nested material counted as meshed (meshing them is part of the estimate)."""
    _, nested = _nested_solids(_manifold(), comp, segments, None)
    return solid_triangles(comp, segments, nested)

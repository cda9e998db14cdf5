"""The data-only lattice description, format ``ple-lattice/1`` (SPEC §5): dicts to and from lattices.

Loading never runs code. Every validation error names the offending field with a
JSON path such as ``U.similarity.axis`` or ``beams[3].to``.
"""

from __future__ import annotations

import math

import numpy as np

from ..algebra.mobius import Mobius
from ..algebra.similarity import Similarity, similarity_from_dict
from ..algebra.vectors import as3
from ..errors import PleError, cut, echo
from .becots import BeCOTSField, Stack
from .budget import check_lattice
from .grading import grade_from_dict, grade_to_dict
from .lattice import Lattice
from .mobius import MobiusGroups, mobius_lattice
from .schema import check_ir

FORMAT = "ple-lattice/1"


def _num(x, where: str) -> float:
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        raise PleError(f"{where}: expected a number, got {echo(x)}")
    if not math.isfinite(float(x)):
        raise PleError(f"{where}: must be finite, got {echo(x)}")
    return float(x)


def _vec3(x, where: str) -> list[float]:
    if not isinstance(x, list) or len(x) != 3:
        raise PleError(f"{where}: expected a list of 3 numbers, got {echo(x)}")
    return [_num(c, f"{where}[{n}]") for n, c in enumerate(x)]


def _similarity(d, where: str) -> Similarity:
    """``{"matrix": 4x4}`` or ``{"similarity": {"kind": ...}}``."""
    if not isinstance(d, dict):
        raise PleError(f"{where}: expected an object")
    if ("matrix" in d) == ("similarity" in d):
        raise PleError(f"{where}: give exactly one of 'matrix' or 'similarity'")
    if "matrix" in d:
        m = d["matrix"]
        if not isinstance(m, list) or len(m) != 4 or any(not isinstance(row, list) or len(row) != 4 for row in m):
            raise PleError(f"{where}.matrix: expected 4 rows of 4 numbers")
        vals = [[_num(v, f"{where}.matrix[{r}][{c}]") for c, v in enumerate(row)] for r, row in enumerate(m)]
        return Similarity.from_matrix(np.array(vals), f"{where}.matrix")
    sim = d["similarity"]
    if isinstance(sim, dict):
        for key, val in sim.items():
            if key in ("axis", "point", "vector"):
                _vec3(val, f"{where}.similarity.{key}")
            elif key in ("angle", "factor", "distance"):
                _num(val, f"{where}.similarity.{key}")
    return similarity_from_dict(sim, f"{where}.similarity")


def lattice_from_dict(data, filter_from_dict=None, surface_grade=None) -> Lattice:
    """Build a Lattice from parsed ``ple-lattice/1`` data (validated). The optional ``"filter"``
    field is parsed by ``filter_from_dict(data, where)`` (``ple.filters.ir`` gives one: filters
    live above the model); without it a filtered file is refused, never silently unfiltered.
    The optional ``"grade"`` (a radius field) is ``grade_from_dict``'s; a surface grade is made by
    ``surface_grade(lat, depth, f_surface, f_deep, where)`` from the lattice's body."""
    if not isinstance(data, dict):
        raise PleError("lattice file: expected a JSON object at the top level")
    if data.get("format") != FORMAT:
        raise PleError(f"format: expected {echo(FORMAT)}, got {echo(data.get('format'))}")
    check_ir(data)  # the one schema: unknown keys, types, ranges, sizes (ple.model.schema)
    lat = Lattice()
    nodes = data.get("nodes")
    if not isinstance(nodes, list) or not nodes:
        raise PleError("nodes: expected a non-empty list of nodes")
    labels: set = set()  # the node ids seen: a set, not a scan per node
    for n, node in enumerate(nodes):
        where = f"nodes[{n}]"
        if not isinstance(node, dict):
            raise PleError(f"{where}: expected an object with center and radius")
        for key in ("center", "radius"):
            if key not in node:
                raise PleError(f"{where}.{key}: missing")
        center = _vec3(node["center"], f"{where}.center")
        radius = _num(node["radius"], f"{where}.radius")
        if radius <= 0:
            raise PleError(f"{where}.radius: must be positive, got {radius}")
        name = node.get("id")
        if name is not None and not isinstance(name, (str, int)) or isinstance(name, bool):
            raise PleError(f"{where}.id: must be a string or an integer")
        if isinstance(name, int) and name != n:
            raise PleError(f"{where}.id: an integer id must equal the node's position {n}")
        label = name if isinstance(name, str) else None
        if label is not None and label in labels:
            raise PleError(f"{where}.id: {echo(label)} is used twice")
        labels.add(label)
        lat.add_node(center, radius, label)
    for b, beam in enumerate(data.get("beams", [])):
        where = f"beams[{b}]"
        if not isinstance(beam, dict):
            raise PleError(f"{where}: expected an object with from, to, offset")
        for key in ("from", "to"):
            if key not in beam:
                raise PleError(f"{where}.{key}: missing")
            try:
                lat.node_id(beam[key])
            except PleError:
                raise PleError(f"{where}.{key}: unknown node id {echo(beam[key])}") from None
        offset = beam.get("offset", [0, 0, 0])
        if (not isinstance(offset, list) or len(offset) != 3
                or any(isinstance(x, bool) or not isinstance(x, int) for x in offset)):
            raise PleError(f"{where}.offset: expected 3 integers, got {echo(offset)}")
        try:
            lat.add_beam(beam["from"], beam["to"], *offset)
        except PleError as exc:
            raise PleError(f"{where}: {exc}") from None
    if "mobius" in data:
        clash = [k for k in ("U", "V", "W", "placement", "becots") if k in data]
        if clash:
            raise PleError(f"{clash[0]}: a Möbius lattice places its groups by mobius.U, V, W and frame; "
                           f"remove {clash[0]}")
        lat = mobius_from_ir(lat, data["mobius"], "mobius")
    for name in ("U", "V", "W"):
        if name not in data:
            continue
        d = data[name]
        if not isinstance(d, dict):
            raise PleError(f"{name}: expected an object with count and a similarity")
        count = d.get("count", 1)
        if isinstance(count, bool) or not isinstance(count, int):
            raise PleError(f"{name}.count: expected an integer, got {echo(count)}")
        cumulative = d.get("cumulative", False)
        if not isinstance(cumulative, bool):
            raise PleError(f"{name}.cumulative: expected true or false")
        sim = _similarity({k: v for k, v in d.items() if k in ("matrix", "similarity")}, name)
        try:
            getattr(lat, f"set_{name.lower()}")(count, sim, cumulative)
        except PleError as exc:
            raise PleError(f"{name}.count: {exc}") from None
    if "placement" in data:
        lat.set_placement(_similarity(data["placement"], "placement"))
    if "becots" in data:
        becots_from_ir(lat, data["becots"], "becots")
    if "description" in data:
        lat.meta["description"] = str(data["description"])
    check_lattice(lat)
    if "filter" in data:  # validated by filter_from_dict (ple.filters.ir), not by the schema
        if filter_from_dict is None:
            raise PleError("filter: this reader cannot apply filters (load the file with ple.io.irfile.load_ir)")
        lat.set_filter(filter_from_dict(data["filter"], "filter"))
    if "grade" in data:
        surface = None if surface_grade is None else (lambda *a: surface_grade(lat, *a))
        lat.set_radius_field(grade_from_dict(data["grade"], "grade", surface))
    return lat


def _matrix_list(s: Similarity) -> list[list[float]]:
    return [[float(x) for x in row] for row in s.matrix]


def lattice_to_dict(lat: Lattice, resolved: bool = True, filter_to_dict=None, field_to_dict=None) -> dict:
    """The IR of a lattice. ``resolved``: every U/V/W as its incremental 4x4 matrix (what
    ``ple ir`` writes); otherwise canonical similarities with their cumulative flags. A filter is
    written by ``filter_to_dict(filter)`` (``ple.filters.ir``); without it a filtered lattice is
    refused rather than written unfiltered. A radius field is written by ``field_to_dict``
    (default ``grade_to_dict``: linear and grid fields)."""
    if lat.group_map is not None and not isinstance(lat.group_map, MobiusGroups):
        raise PleError(f"a lattice placed by a {lat.group_map.kind} map has no ple-lattice/1 form "
                       "(keep its program instead)")
    out: dict = {"format": FORMAT}
    if lat.meta.get("description"):
        out["description"] = lat.meta["description"]
    out["nodes"] = [{"id": n.name if n.name is not None else i, "center": [float(c) for c in n.center],
                     "radius": float(n.radius)} for i, n in enumerate(lat.nodes)]

    def ref(i: int):
        return lat.nodes[i].name if lat.nodes[i].name is not None else i

    out["beams"] = [{"from": ref(b.n1), "to": ref(b.n2), "offset": [b.di, b.dj, b.dk]} for b in lat.beams]
    if lat.group_map is not None:  # a Möbius lattice: its exact matrices, resolved or not
        out["mobius"] = mobius_to_ir(lat.group_map, lat.counts)
    for name, d in (("U", lat.u), ("V", lat.v), ("W", lat.w)):
        if lat.group_map is not None:
            break
        if resolved:
            out[name] = {"count": d.count, "matrix": _matrix_list(d.incremental)}
        else:
            entry = {"count": d.count, "similarity": d.similarity.to_dict()}
            if d.cumulative:
                entry["cumulative"] = True
            out[name] = entry
    if lat.group_map is None:
        out["placement"] = ({"matrix": _matrix_list(lat.placement)} if resolved
                            else {"similarity": lat.placement.to_dict()})
    if lat.becots is not None and not resolved:
        out["becots"] = lat.becots.to_ir()
        del out["U"], out["V"]
    if lat.filter is not None:
        if filter_to_dict is None:
            raise PleError("filter: this writer cannot write filters (use ple.io.irfile.save_ir)")
        out["filter"] = filter_to_dict(lat.filter)
    if lat.radius_field is not None:
        out["grade"] = (field_to_dict or grade_to_dict)(lat.radius_field)
    return out


# ----- Möbius steady patterns (thesis §11.3): exact data, bit for bit -----------------------------
MOBIUS_NORMALIZED = 1e-12  # |ad - bc - 1| within this: the matrix is kept as written (no rounding)


def _complex_matrix(m: np.ndarray) -> list:
    return [[[float(z.real), float(z.imag)] for z in row] for row in np.asarray(m, dtype=complex)]


def _mobius_matrix(x, where: str) -> np.ndarray:
    """A complex 2x2 matrix from ``[[[re, im], [re, im]], [[re, im], [re, im]]]`` (schema-checked):
    kept as written when already normalized (ad - bc = 1), normalized otherwise; ad - bc = 0 refused."""
    m = np.array([[complex(*z) for z in row] for row in x], dtype=complex)
    det = m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0]
    if abs(det) <= 1e-13 * max(1.0, float(np.abs(m).max())) ** 2:
        raise PleError(f"{where}: ad - bc = 0 defines no Möbius transformation")
    if abs(det - 1) <= MOBIUS_NORMALIZED:
        return m
    try:
        return Mobius.from_coefficients(*m.reshape(-1)).m
    except PleError as exc:
        raise PleError(f"{where}: {exc}") from None


def _mobius_from_entry(d: dict, where: str) -> Mobius:
    """One Möbius transformation: its ``matrix`` and, when given, its ``split`` U = R ∘ S ∘ R
    (§11.2.3: the similarity S, with its angle beyond ±π if so, and the inversion's matrix M_R),
    which its real powers use."""
    m = _mobius_matrix(d["matrix"], f"{where}.matrix")
    if "split" not in d:
        return Mobius(m)
    sp = d["split"]
    c = sp["similarity"]
    axis = np.asarray(c["axis"], dtype=float)
    if abs(float(np.linalg.norm(axis)) - 1) > 1e-12:
        raise PleError(f"{where}.split.similarity.axis: must be a unit vector, got {c['axis']}")
    sim = Similarity(float(c["factor"]), float(c["angle"]), tuple(float(x) for x in c["axis"]),
                     tuple(float(x) for x in c["point"]), float(c["distance"]))
    mr = np.array([[complex(*z) for z in row] for row in sp["inversion"]], dtype=complex)
    if abs(mr[0, 0] * mr[1, 1] - mr[0, 1] * mr[1, 0]) == 0:
        raise PleError(f"{where}.split.inversion: ad - bc = 0 is no inversion")
    out = Mobius(m, (sim, mr))
    if not (out ** 1.0).allclose(Mobius(m), 1e-8):
        raise PleError(f"{where}.split: R ∘ S ∘ R is not the matrix (U = R ∘ S ∘ R, thesis §11.2.3)")
    return out


def mobius_from_ir(template: Lattice, data: dict, where: str = "mobius") -> Lattice:
    """The Möbius lattice of ``template`` and the IR ``"mobius"`` object (schema-checked): group
    (i, j, k) placed by ``W**k ∘ V**j ∘ U**i ∘ frame`` (§11.3); a missing direction is the identity."""
    ident = Mobius.identity()
    gs, counts = [], []
    for name in ("U", "V", "W"):
        d = data.get(name)
        gs.append(ident if d is None else _mobius_from_entry(d, f"{where}.{name}"))
        counts.append(1 if d is None else d.get("count", 1))
    frame = _mobius_from_entry(data["frame"], f"{where}.frame") if "frame" in data else ident
    return mobius_lattice(template, gs[0], gs[1], gs[2], tuple(counts), frame)


def mobius_to_ir(gm: MobiusGroups, counts) -> dict:
    """The ``"mobius"`` object of a Möbius lattice: each normalized matrix as written in memory
    (every float exact in JSON) and the split its powers use, so that reading it back evaluates
    to the same bits."""
    def entry(g: Mobius, count=None) -> dict:
        out = {} if count is None else {"count": int(count)}
        out["matrix"] = _complex_matrix(g.m)
        if g.split is not None:
            s, mr = g.split
            out["split"] = {"similarity": {"factor": float(s.factor), "angle": float(s.angle),
                                           "axis": [float(x) for x in s.axis], "point": [float(x) for x in s.point],
                                           "distance": float(s.distance)},
                            "inversion": _complex_matrix(mr)}
        return out

    out = {name: entry(g, n) for name, g, n in (("U", gm.u, counts[0]), ("V", gm.v, counts[1]),
                                                  ("W", gm.w, counts[2]))}
    out["frame"] = entry(gm.frame)
    return out


def becots_from_ir(lat: Lattice, data, where: str = "becots") -> None:
    """Apply the IR ``"becots"`` object (SPEC §5) to ``lat``; errors name the offending field."""
    if not isinstance(data, dict):
        raise PleError(f"{where}: expected an object with corners and counts")
    unknown = sorted(set(data) - {"corners", "counts", "branch", "closed", "field", "stack"})
    if unknown:
        raise PleError(f"{where}.{cut(unknown[0])}: unknown field")
    if ("corners" in data) == ("field" in data):
        raise PleError(f"{where}: give exactly one of 'corners' or 'field'")
    if "counts" not in data:
        raise PleError(f"{where}.counts: missing")
    counts = data["counts"]
    if not isinstance(counts, list) or len(counts) != 2 or any(isinstance(n, bool) or not isinstance(n, int)
                                                               for n in counts):
        raise PleError(f"{where}.counts: expected two integers [nu, nv], got {echo(counts)}")
    closed = data.get("closed", False)
    if not isinstance(closed, bool):
        raise PleError(f"{where}.closed: expected true or false")
    try:
        if "corners" in data:
            corners = data["corners"]
            if not isinstance(corners, list) or len(corners) != 4:
                raise PleError(f"{where}.corners: expected 4 points [A, B, C, D]")
            pts = [_ir_point(p, f"{where}.corners[{n}]") for n, p in enumerate(corners)]
            fld = BeCOTSField.from_corners(*pts, branch=data.get("branch", (0, 0)))
        else:
            fld = BeCOTSField.from_dict(data["field"], f"{where}.field")
        stack = _stack_from_ir(data["stack"], lat, f"{where}.stack") if "stack" in data else None
        lat.set_field(fld, counts, closed, stack)
    except PleError as exc:
        msg = str(exc)
        raise PleError(msg if msg.startswith(where) else f"{where}: {msg}") from None


def _ir_point(p, where: str) -> np.ndarray:
    if not isinstance(p, list) or len(p) != 3 or any(isinstance(x, bool) or not isinstance(x, (int, float)) for x in p):
        raise PleError(f"{where}: expected 3 numbers, got {echo(p)}")
    return as3(p, where)


def _stack_from_ir(d, lat: Lattice, where: str) -> Stack:
    if not isinstance(d, dict):
        raise PleError(f"{where}: expected an object")
    try:
        layers, per = int(d["layers"]), int(d["nodes_per_layer"])
        step = as3(d["step"], f"{where}.step")
    except KeyError as exc:
        raise PleError(f"{where}.{exc.args[0]}: missing") from None
    except (TypeError, ValueError):
        raise PleError(f"{where}: layers and nodes_per_layer must be integers") from None
    if layers < 1 or per < 1 or layers * per != len(lat.nodes):
        raise PleError(f"{where}: {layers} layers × {per} nodes do not match the {len(lat.nodes)} template nodes")
    return Stack(layers, per, step, str(d.get("mode", "raise")))

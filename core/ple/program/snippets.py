"""Code snippets of GUI edits and program rewriting (thesis §6.2.2, Fig. 6.3).

Every GUI manipulation is an *edit*: ``SetDirection`` (a frame moved or a repetition count
changed: ``set_u/set_v/set_w``), ``SetPlacement``, ``AddNode``, ``MoveNode``, ``RemoveNode``,
``AddBeam``, ``RemoveBeam``, ``SetBecots`` (moved BeCOTS corners). Edits apply to a Lattice
(``apply_to_lattice``), print as program lines (``snippet``) and rewrite a program's text
(``apply_edits``): calls an edit replaces are rewritten in place through the syntax tree's
positions where that is safe, the rest become lines inserted before ``return lat``; comments
and unrelated code are kept, and re-running the new program reproduces the GUI state
(checked before the text is returned).
"""

from __future__ import annotations

import ast
import json
from dataclasses import asdict, dataclass

import numpy as np

from ..algebra.similarity import Similarity, similarity_from_dict
from ..algebra.vectors import Pt
from ..errors import PleError, echo
from ..model.lattice import Lattice
from .runtime import compile_program, trace_program

DIGITS = 12  # decimals written for numbers: far below the 1e-9 round-trip tolerance


def _num(x: float, digits: int = DIGITS) -> str:
    v = round(float(x), digits)
    return repr(0.0 if v == 0 else v).removesuffix(".0") if v == int(v) else repr(v)


def _pt(c, digits: int = DIGITS) -> str:
    return f"Pt({', '.join(_num(x, digits) for x in c)})"


@dataclass(frozen=True)
class SetDirection:
    """``set_u/set_v/set_w``: ``count`` None keeps the count, ``similarity`` None keeps the
    similarity and its cumulative flag (a count-only edit, e.g. from the count slider)."""

    axis: str
    count: int | None = None
    similarity: Similarity | None = None
    cumulative: bool = False

    def __post_init__(self):
        if self.axis not in ("u", "v", "w"):
            raise PleError(f"edit: axis must be u, v or w, got {echo(self.axis)}")
        if self.count is None and self.similarity is None:
            raise PleError(f"edit set_{self.axis}: nothing to change")

    def apply(self, lat: Lattice) -> None:
        d = getattr(lat, self.axis)
        count = d.count if self.count is None else self.count
        if self.similarity is None:
            sim, cum = d.similarity, d.cumulative
        else:
            sim, cum = self.similarity, self.cumulative
        getattr(lat, f"set_{self.axis}")(count, sim, cum)

    def code(self, var: str, digits: int, state: Lattice | None = None) -> str:
        d = f"{var}.{self.axis}"
        count = str(self.count) if self.count is not None else (
            str(getattr(state, self.axis).count) if state is not None else f"{d}.count")
        if self.similarity is None:
            return f"{var}.set_{self.axis}({count}, {d}.similarity, cumulative={d}.cumulative)"
        cum = ", cumulative=True" if self.cumulative else ""
        return f"{var}.set_{self.axis}({count}, {self.similarity.to_code(digits)}{cum})"


@dataclass(frozen=True)
class SetPlacement:
    similarity: Similarity

    def apply(self, lat: Lattice) -> None:
        lat.set_placement(self.similarity)

    def code(self, var: str, digits: int, state: Lattice | None = None) -> str:
        return f"{var}.set_placement({self.similarity.to_code(digits)})"


@dataclass(frozen=True)
class AddNode:
    center: tuple
    radius: float
    name: str | None = None

    def apply(self, lat: Lattice) -> None:
        lat.add_node(Pt(self.center), self.radius, self.name)

    def code(self, var: str, digits: int, state: Lattice | None = None) -> str:
        name = f", {self.name!r}" if self.name is not None else ""
        return f"{var}.add_node({_pt(self.center, digits)}, {_num(self.radius, digits)}{name})"


@dataclass(frozen=True)
class MoveNode:
    """Move and/or resize template node ``index`` (None keeps centre or radius)."""

    index: int
    center: tuple | None = None
    radius: float | None = None

    def apply(self, lat: Lattice) -> None:
        node = lat.nodes[_node_index(lat, self.index)]
        if self.center is not None:
            node.center = Pt(self.center)
        if self.radius is not None:
            if not float(self.radius) > 0:
                raise PleError(f"node {self.index}: radius must be positive, got {self.radius}")
            node.radius = float(self.radius)

    def code(self, var: str, digits: int, state: Lattice | None = None) -> str:
        lines = []
        if self.center is not None:
            lines.append(f"{var}.nodes[{self.index}].center = {_pt(self.center, digits)}")
        if self.radius is not None:
            lines.append(f"{var}.nodes[{self.index}].radius = {_num(self.radius, digits)}")
        return "\n".join(lines)


@dataclass(frozen=True)
class RemoveNode:
    index: int

    def apply(self, lat: Lattice) -> None:
        lat.remove_node(_node_index(lat, self.index))

    def code(self, var: str, digits: int, state: Lattice | None = None) -> str:
        return f"{var}.remove_node({self.index})"


@dataclass(frozen=True)
class AddBeam:
    n1: int
    n2: int
    di: int = 0
    dj: int = 0
    dk: int = 0

    def apply(self, lat: Lattice) -> None:
        lat.add_beam(self.n1, self.n2, self.di, self.dj, self.dk)

    def code(self, var: str, digits: int, state: Lattice | None = None) -> str:
        return f"{var}.add_beam({self.n1}, {self.n2}, {self.di}, {self.dj}, {self.dk})"


@dataclass(frozen=True)
class RemoveBeam:
    index: int

    def apply(self, lat: Lattice) -> None:
        lat.remove_beam(self.index)

    def code(self, var: str, digits: int, state: Lattice | None = None) -> str:
        return f"{var}.remove_beam({self.index})"


@dataclass(frozen=True)
class SetBecots:
    """``set_becots(A, B, C, D, counts=(nu, nv))``: a BeCOTS slab from moved corners (§4.2)."""

    corners: tuple
    counts: tuple

    def apply(self, lat: Lattice) -> None:
        lat.set_becots(*(Pt(c) for c in self.corners), counts=tuple(int(n) for n in self.counts))

    def code(self, var: str, digits: int, state: Lattice | None = None) -> str:
        pts = ", ".join(_pt(c, digits) for c in self.corners)
        return f"{var}.set_becots({pts}, counts=({int(self.counts[0])}, {int(self.counts[1])}))"


EDIT_TYPES = {c.__name__: c for c in (SetDirection, SetPlacement, AddNode, MoveNode, RemoveNode, AddBeam, RemoveBeam,
                                      SetBecots)}
Edit = SetDirection | SetPlacement | AddNode | MoveNode | RemoveNode | AddBeam | RemoveBeam | SetBecots


def _node_index(lat: Lattice, index: int) -> int:
    if not 0 <= int(index) < len(lat.nodes):
        raise PleError(f"template node {index} does not exist (the template has {len(lat.nodes)} nodes)")
    return int(index)


# ----- edit lists --------------------------------------------------------------------------------
def apply_to_lattice(lat: Lattice, edits) -> Lattice:
    """A copy of ``lat`` with the edits applied in order."""
    out = lat.copy()
    for e in edits:
        e.apply(out)
    return out


def coalesce(edits) -> list:
    """Shorter equivalent edit list: a later full ``SetDirection`` (or ``SetPlacement``)
    replaces earlier ones of its axis (they commute with node and beam edits); a count-only
    edit merges into the preceding one; consecutive moves of one node merge."""
    out: list = []
    for e in edits:
        if isinstance(e, SetDirection):
            prev = [x for x in out if isinstance(x, SetDirection) and x.axis == e.axis]
            if e.similarity is None and prev and prev[-1].similarity is not None:
                e = SetDirection(e.axis, e.count if e.count is not None else prev[-1].count,
                                 prev[-1].similarity, prev[-1].cumulative)
            elif e.count is None and prev and prev[-1].count is not None:
                e = SetDirection(e.axis, prev[-1].count, e.similarity, e.cumulative)
            out = [x for x in out if x not in prev]
        elif isinstance(e, (SetPlacement, SetBecots)):
            out = [x for x in out if not isinstance(x, type(e))]
        elif isinstance(e, MoveNode) and out and isinstance(out[-1], MoveNode) and out[-1].index == e.index:
            last = out.pop()
            e = MoveNode(e.index, e.center if e.center is not None else last.center,
                         e.radius if e.radius is not None else last.radius)
        out.append(e)
    return out


def snippet(edits, var: str = "lat", digits: int = DIGITS, state: Lattice | None = None) -> str:
    """Program lines of the edits (Fig. 6.3); ``state`` fills in unchanged counts."""
    return "\n".join(e.code(var, digits, state) for e in coalesce(edits))


def edits_to_json(edits) -> str:
    out = []
    for e in edits:
        d = asdict(e)
        for key, val in list(d.items()):
            if isinstance(getattr(e, key), Similarity):
                d[key] = getattr(e, key).to_dict()
            elif key == "corners":
                d[key] = [[float(x) for x in c] for c in val]
            elif isinstance(val, tuple):
                d[key] = [float(x) for x in val] if key != "counts" else [int(x) for x in val]
        out.append({"type": type(e).__name__, **d})
    return json.dumps(out)


def edits_from_json(text: str) -> list:
    try:
        data = json.loads(text or "[]")
    except json.JSONDecodeError as exc:
        raise PleError(f"edit list: malformed JSON ({exc.msg})") from None
    out = []
    for n, d in enumerate(data):
        cls = EDIT_TYPES.get(d.get("type")) if isinstance(d, dict) else None
        if cls is None:
            raise PleError(f"edit list[{n}]: unknown edit {echo(d)}")
        args = {k: v for k, v in d.items() if k != "type"}
        for key in ("similarity",):
            if args.get(key) is not None:
                args[key] = similarity_from_dict(args[key], f"edit list[{n}].{key}")
        if args.get("center") is not None:
            args["center"] = tuple(args["center"])
        if "corners" in args:
            args["corners"] = tuple(tuple(c) for c in args["corners"])
            args["counts"] = tuple(args["counts"])
        out.append(cls(**args))
    return out


# ----- rewriting program text ------------------------------------------------------------------
def _is_call(node: ast.AST, var: str, method: str) -> bool:
    return (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == method
            and isinstance(node.func.value, ast.Name) and node.func.value.id == var)


class _Source:
    """Program text addressed by ast positions (line numbers from 1, UTF-8 byte columns)."""

    def __init__(self, text: str):
        self.text = text
        self.lines = text.splitlines(keepends=True)
        self.starts = np.cumsum([0] + [len(x) for x in self.lines]).tolist()

    def offset(self, line: int, col: int) -> int:
        return self.starts[line - 1] + len(self.lines[line - 1].encode()[:col].decode())

    def span(self, node: ast.AST) -> tuple[int, int]:
        return self.offset(node.lineno, node.col_offset), self.offset(node.end_lineno, node.end_col_offset)

    def segment(self, node: ast.AST) -> str:
        a, b = self.span(node)
        return self.text[a:b]


def _lattice_function(tree: ast.Module) -> ast.FunctionDef:
    for stmt in tree.body:
        if isinstance(stmt, ast.FunctionDef) and stmt.name == "lattice":
            return stmt
    raise PleError("program: no top-level function lattice(...) to apply edits to")


def apply_edits(source: str, edits, params: dict | None = None, digits: int = DIGITS,
                name: str = "<program>", in_place: bool = True) -> str:
    """Rewrite program text so that running it gives the program's lattice with ``edits``.

    ``set_u/v/w`` and ``set_placement`` calls and ``add_node`` arguments are replaced in
    place when that is unambiguous (one top-level call); other edits become lines inserted
    before the final top-level ``return <lattice>``. The result is verified by running old
    and new program with ``params``; if an in-place rewrite changed the meaning (e.g. later
    code reads what it replaced), the edits are appended instead.
    """
    edits = coalesce(edits)
    source = _named_return(source)
    prog = compile_program(source, name)
    executed = _executed_lines(prog, name, params or {})
    expected = apply_to_lattice(prog.run(**(params or {})), edits)
    candidates = [True, False] if in_place else [False]
    for use_in_place in candidates:
        text = _rewrite(source, edits, digits, use_in_place, executed)
        got = compile_program(text, name).run(**(params or {}))
        if lattices_close(got, expected):
            return text
    raise PleError(f"{name}: applying the edits does not reproduce the GUI state; copy the snippet instead")


def _named_return(source: str) -> str:
    """``return <expression>`` at the end of lattice() becomes ``lat = <expression>`` and
    ``return lat`` (a fresh name if ``lat`` is taken), so edits have a lattice to act on."""
    try:
        fn = _lattice_function(ast.parse(source))
    except (SyntaxError, PleError):
        return source  # reported as usual by compile_program / _rewrite
    ret = fn.body[-1] if fn.body else None
    if not isinstance(ret, ast.Return) or ret.value is None or isinstance(ret.value, ast.Name):
        return source
    used = {n.id for n in ast.walk(fn) if isinstance(n, ast.Name)} | {a.arg for a in ast.walk(fn)
                                                                       if isinstance(a, ast.arg)}
    var = next(v for v in ("lat", "lattice_", *(f"lat{n}" for n in range(1, 100))) if v not in used)
    src = _Source(source)
    start, end = src.span(ret)
    indent = " " * ret.col_offset
    return source[:start] + f"{var} = {src.segment(ret.value)}\n{indent}return {var}" + source[end:]


def _executed_lines(prog, name: str, params: dict) -> set[int] | None:
    """Line numbers of lattice() that run with ``params`` (which branch holds the live calls);
    None if tracing is not possible."""
    lines: set[int] = set()

    def local(frame, event, arg):
        if event == "line":
            lines.add(frame.f_lineno)
        return local

    try:
        with trace_program(name, local):
            prog.run(**params)
    except PleError:
        return None
    return lines


def _rewrite(source: str, edits, digits: int, in_place: bool, executed: set[int] | None = None) -> str:
    tree = ast.parse(source)
    fn = _lattice_function(tree)
    ret = fn.body[-1] if fn.body else None
    if not (isinstance(ret, ast.Return) and isinstance(ret.value, ast.Name)):
        raise PleError("program: lattice() must end with `return <name>` at its top level to apply edits")
    var = ret.value.id
    src = _Source(source)
    calls = [n for n in ast.walk(fn) if isinstance(n, ast.Call)]
    top = {id(s.value): s for s in fn.body if isinstance(s, (ast.Expr, ast.Assign)) and isinstance(s.value, ast.Call)}

    statements = {id(s.value) for s in ast.walk(fn) if isinstance(s, ast.Expr) and isinstance(s.value, ast.Call)}

    def live_calls(method: str) -> list:
        """The calls to rewrite in place: the one top-level call, or else the statement calls
        (in branches, loops) that run with the given inputs; [] if any is used as a value."""
        found = [c for c in calls if _is_call(c, var, method)]
        if len(found) == 1 and id(found[0]) in top:
            return found
        if not found or any(id(c) not in statements for c in found):
            return []
        live = [c for c in found if executed is None or c.lineno in executed]
        return live if live and executed is not None else []

    replacements: dict[tuple[int, int], str] = {}  # by span: a later edit of the same span wins
    appended: list[str] = []
    node_calls = [c for c in calls if _is_call(c, var, "add_node")]
    nodes_in_place = in_place and all(id(c) in top for c in node_calls)
    shifted = False  # after a node is added or removed, node indices no longer match calls
    for e in edits:
        live: list = []
        if in_place and isinstance(e, SetDirection):
            live = live_calls(f"set_{e.axis}")
        elif in_place and isinstance(e, SetPlacement):
            live = live_calls("set_placement")
        elif in_place and isinstance(e, SetBecots):
            live = live_calls("set_becots")
            if live:
                for call in live:
                    replacements[src.span(call)] = e.code(var, digits)
                continue
        if live and isinstance(e, SetPlacement) and all(not c.keywords and len(c.args) == 1 for c in live):
            for call in live:
                replacements[src.span(call.args[0])] = e.similarity.to_code(digits)
            continue
        if live and isinstance(e, SetDirection) and all(
                2 <= len(c.args) + len(c.keywords) <= 3 and len(c.args) >= 2 for c in live):
            for call in live:
                count = str(e.count) if e.count is not None else src.segment(call.args[0])
                if e.similarity is None:
                    rest = ", ".join([src.segment(a) for a in call.args[1:]]
                                     + [src.segment(k) for k in call.keywords])
                else:
                    rest = e.similarity.to_code(digits) + (", cumulative=True" if e.cumulative else "")
                start, _ = src.span(call.args[0])
                last = (call.keywords or call.args)[-1]
                _, end = src.span(last)
                replacements[(start, end)] = f"{count}, {rest}"
            continue
        if isinstance(e, (AddNode, RemoveNode)):
            shifted = True
        if isinstance(e, MoveNode) and nodes_in_place and not shifted and e.index < len(node_calls):
            call = node_calls[e.index]
            if len(call.args) >= 2:
                if e.center is not None:
                    replacements[src.span(call.args[0])] = _pt(e.center, digits)
                if e.radius is not None:
                    replacements[src.span(call.args[1])] = _num(e.radius, digits)
                continue
        appended.append(e.code(var, digits))
    text = source
    for (start, end), new in sorted(replacements.items(), reverse=True):
        text = text[:start] + new + text[end:]
    if appended:
        line = ret.lineno
        indent = " " * ret.col_offset
        block = "".join(f"{indent}{ln}\n" for a in appended for ln in a.splitlines())
        # replacements lie above the return statement: shift its line by the lines they added
        lines = text.splitlines(keepends=True)
        shift = text.count("\n", 0, len(text)) - source.count("\n")
        lines.insert(line - 1 + shift, block)
        text = "".join(lines)
    return text


def lattices_close(a: Lattice, b: Lattice, tol: float = 1e-9) -> bool:
    """Same template, beam-patterns, counts and similarities (matrices within ``tol``)."""
    beams = lambda lat: [(x.n1, x.n2, x.di, x.dj, x.dk) for x in lat.beams]  # noqa: E731 - any copy of the core
    if a.counts != b.counts or len(a.nodes) != len(b.nodes) or beams(a) != beams(b):
        return False
    if not np.allclose(a.template_centers, b.template_centers, rtol=0, atol=tol):
        return False
    if not np.allclose(a.template_radii, b.template_radii, rtol=0, atol=tol):
        return False
    return all(x.allclose(y, tol) for x, y in ((a.U, b.U), (a.V, b.V), (a.W, b.W), (a.placement, b.placement)))

"""The layers of the core (docs/architecture.md), enforced: imports run downward only, no cycles,
no library module reaches the doors (cli, bench, tools, the add-on), query backends never import
their dispatcher, meshing writes no files, and function-local imports are only for optional
third-party packages (and trimesh, a cost small jobs do not pay). Imports are read with ``ast``,
function-local ones included."""

from __future__ import annotations

import ast
import functools
import re
import shutil
from pathlib import Path

import pytest

CORE = Path(__file__).resolve().parent.parent / "core" / "ple"
# rank of each top-level part of the package: a module may import only parts of lower rank
# (or modules of its own part, without cycles); measure and meshing stand side by side
RANK = {"errors": 0, "algebra": 1, "model": 2, "queries": 3, "filters": 4, "clg": 4.5, "measure": 5, "meshing": 5,
        "io": 6, "program": 7, "app": 8, "bench": 9, "cli": 10, "presets": 11}
LIBRARY = {"errors", "algebra", "model", "queries", "filters", "clg", "measure", "meshing", "io", "program", "app"}
DOORS = ("cli", "bench")  # inside the package, above the library
OUTSIDE = ("tools", "ple_addon")  # repository tools and the Blender add-on
OPTIONAL = {"scipy", "manifold3d", "PIL", "lib3mf", "bpy", "mathutils", "addon_utils", "dask", "distributed", "fsspec",
            "resource"}  # resource: POSIX only (the runner falls back where it is missing)
# required, but imported where used: half a second that a small job (a streamed STL, info, check) does not pay
LAZY = {"trimesh"}
QUERY_DISPATCHER = "ple.queries.biq"
# optional C extensions (setup.py), imported in a try
COMPILED = {"ple.io._stlcodec", "ple.meshing._assemble", "ple.meshing._selfcheck", "ple.queries._rangefinder"}
DOOR_NAMES = re.compile(r"\bple\.(cli|bench)\b|\bple_addon\b|\btools\.\w")  # also in strings (subprocess)
WRITES = {"write_text", "write_bytes", "savez", "savez_compressed", "save", "tofile", "export", "dump"}


@functools.cache
def _nodes(text: str) -> tuple[ast.AST, ...]:
    """Every node of a module's syntax tree, parsed and walked once per text (the checker's
    self-tests read copies of the same files again and again)."""
    return tuple(ast.walk(ast.parse(text)))


def modules(root: Path) -> dict[str, Path]:
    out = {}
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root.parent).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _target(mod: str, is_pkg: bool, node: ast.ImportFrom, alias: str, known: dict) -> str:
    if node.level:
        base = mod.split(".") if is_pkg else mod.split(".")[:-1]
        base = base[:len(base) - (node.level - 1)]
        name = ".".join(base + ([node.module] if node.module else []))
    else:
        name = node.module or ""
    sub = f"{name}.{alias}"
    return sub if sub in known or sub in COMPILED else name


def imports(root: Path) -> list[tuple[str, str, int, bool]]:
    """(importer, imported, line, function-local) for every import in the package at ``root``."""
    known = modules(root)
    out = []
    for mod, path in known.items():
        is_pkg = path.name == "__init__.py"
        for node in _nodes(path.read_text()):
            local = getattr(node, "col_offset", 0) > 0
            if isinstance(node, ast.Import):
                out += [(mod, a.name, node.lineno, local) for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                out += [(mod, _target(mod, is_pkg, node, a.name, known), node.lineno, local) for a in node.names]
    return out


def part(name: str) -> str | None:
    bits = name.split(".")
    return bits[1] if bits[0] == "ple" and len(bits) > 1 else None


def cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in edges.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in list(edges):
        if v not in index:
            visit(v)
    return out


def _writes_files(path: Path) -> list[int]:
    lines = []
    for node in _nodes(path.read_text()):
        if not isinstance(node, ast.Call):
            continue
        fn = node.func
        if isinstance(fn, ast.Name) and fn.id == "open":
            mode = node.args[1] if len(node.args) > 1 else next(
                (k.value for k in node.keywords if k.arg == "mode"), None)
            if isinstance(mode, ast.Constant) and set(str(mode.value)) & set("wax+"):
                lines.append(node.lineno)
        elif isinstance(fn, ast.Attribute) and fn.attr in WRITES:
            lines.append(node.lineno)
    return lines


def _private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def private_crossings(root: Path) -> list[str]:
    """Every private name (``_name``) that a module of the package at ``root`` takes from another
    module: ``from m import _name``, or ``m._name`` on a module it imported. A private module of the
    importer's own package (``from . import _baselines``) and the compiled kernels are allowed."""
    known = modules(root)
    found = []
    for mod, path in known.items():
        is_pkg = path.name == "__init__.py"
        package = mod if is_pkg else mod.rsplit(".", 1)[0]
        bound: set[str] = set()  # names the module binds to imported modules
        where = path.relative_to(root.parent)
        for node in _nodes(path.read_text()):
            if isinstance(node, ast.Import):
                bound |= {a.asname for a in node.names if a.asname}
            elif isinstance(node, ast.ImportFrom) and node.module != "__future__":
                for a in node.names:
                    dst = _target(mod, is_pkg, node, a.name, known)
                    if dst in known or dst in COMPILED:
                        bound.add(a.asname or a.name)
                    own = dst == f"{package}.{a.name}"  # a private module of the importer's own package
                    if _private(a.name) and dst not in COMPILED and not own:
                        found.append(f"{where}:{node.lineno}: private name {a.name} imported from {dst}")
        for node in _nodes(path.read_text()):
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in bound \
                    and _private(node.attr):
                found.append(f"{where}:{node.lineno}: private name {node.attr} of the module {node.value.id}")
    return found


def violations(root: Path) -> list[str]:
    """Every broken rule in the package at ``root`` (``.../ple``), one line each."""
    known = modules(root)
    found = []
    edges: dict[str, set[str]] = {}
    for src, dst, line, local in imports(root):
        where = f"{known[src].relative_to(root.parent)}:{line}"
        top = dst.split(".")[0]
        sp, dp = part(src), part(dst)
        if top == "ple":
            if dst in known and dst != src:
                edges.setdefault(src, set()).add(dst)
            if local and dst not in COMPILED:
                found.append(f"{where}: function-local import of {dst} (only optional third-party packages may be)")
            if sp in RANK and dp in RANK and sp != dp and RANK[dp] >= RANK[sp]:
                found.append(f"{where}: {sp} imports {dst}, which is not below it")
            if sp in LIBRARY and dp in DOORS:
                found.append(f"{where}: library module imports the door {dst}")
            if sp == "queries" and dst == QUERY_DISPATCHER and src != QUERY_DISPATCHER:
                found.append(f"{where}: query backend {src} imports the dispatcher {dst}")
        elif top in OUTSIDE and sp in LIBRARY:
            found.append(f"{where}: library module imports {dst}")
        elif local and top not in OPTIONAL | LAZY:
            found.append(f"{where}: function-local import of {dst} (not an optional package)")
    for comp in cycles(edges):
        found.append(f"import cycle: {' -> '.join(comp)}")
    for mod, path in known.items():
        text = path.read_text()
        if part(mod) in LIBRARY and DOOR_NAMES.search(text):
            found.append(f"{path.relative_to(root.parent)}: library module names a door or tool (subprocess?)")
        if part(mod) == "meshing":
            found += [f"{path.relative_to(root.parent)}:{n}: meshing writes a file" for n in _writes_files(path)]
    return found + private_crossings(root)


def test_the_core_keeps_its_layers():
    assert violations(CORE) == []


def test_every_part_is_a_documented_layer():
    for sub in sorted(p for p in CORE.iterdir() if p.is_dir() and p.name != "__pycache__"):
        assert sub.name in RANK, f"{sub.name}: a new part of the core must get a rank here and in docs/architecture.md"
        doc = ast.get_docstring(ast.parse((sub / "__init__.py").read_text()))
        assert doc and doc.strip(), f"{sub.name}/__init__.py needs a docstring saying what the layer holds"
    arch = (CORE.parent.parent / "docs" / "architecture.md").read_text()
    for name in RANK:
        if name != "presets":
            assert f"`{name}" in arch, f"docs/architecture.md does not describe {name}"


@pytest.mark.parametrize("module, text, rule", [
    ("model/bad.py", "from ..queries import biq\n", "not below it"),
    ("model/bad.py", "def f():\n    from ..algebra import vectors\n", "function-local import"),
    ("algebra/bad.py", "import ple.cli.main\n", "imports the door"),
    ("io/bad.py", "import subprocess\nsubprocess.run(['python', '-m', 'ple.cli', 'info'])\n", "names a door"),
    ("queries/bad.py", "from .biq import query\n", "imports the dispatcher"),
    ("meshing/bad.py", "def f(m, p):\n    m.export(p)\n", "meshing writes a file"),
    ("meshing/bad.py", "def f(p):\n    return open(p, 'wb')\n", "meshing writes a file"),
    ("model/bad.py", "from . import bad2\n", "import cycle"),
    ("filters/bad.py", "def f():\n    import numpy\n", "not an optional package"),
    ("meshing/bad.py", "from .tessellate import _ahead\n", "private name _ahead imported"),
    ("bench/bad.py", "from ..queries import rangefinder as rf\nrf._expand(1, 2)\n", "private name _expand of"),
    ("io/bad.py", "import ple.queries.rangefinder as rf\nrf._q({})\n", "private name _q of"),
])
def test_a_forbidden_import_is_caught(tmp_path, module, text, rule):
    """The checker itself: a copy of the core with one bad module breaks exactly that rule."""
    root = tmp_path / "ple"
    shutil.copytree(CORE, root, ignore=shutil.ignore_patterns("__pycache__"))
    (root / module).write_text(text)
    if rule == "import cycle":
        (root / "model" / "bad2.py").write_text("from . import bad\n")
    found = violations(root)
    assert any(rule in v and "bad" in v for v in found), found
    assert all("bad" in v for v in found), found  # nothing else in the copy is reported


# ----- the add-on and the tools ---------------------------------------------------------------------
ADDON = CORE.parent.parent / "ple_addon"
TOOLS = CORE.parent.parent / "tools"
# rank of each add-on module (docs/architecture.md): a module imports only modules of lower rank
ADDON_RANK = {"corelink": 0, "prefs": 0, "session": 1, "draw": 1, "jobs": 1,
              "rig.hooks": 2, "rig.model": 3, "rig.edits": 4, "rig.drawing": 4, "rig.sync": 5, "rig.events": 6,
              "rig": 7,
              "props": 7, "ops.base": 7, "ops.program": 8, "ops.template": 8, "ops.output": 8, "ops": 9, "ui": 9,
              "features": 10, "features.body": 10, "features.clg": 10, "features.mobius": 10, "features.check": 10,
              "": 11, "batch": 11, "build": 11}
MAX_LINES = 400  # no add-on module is longer


def _short(mod: str) -> str:
    return mod.split(".", 1)[1] if "." in mod else ""


def import_cycles(root: Path) -> list[str]:
    """Import circles among the modules of the package at ``root``, function-local imports included."""
    known = modules(root)
    edges: dict[str, set[str]] = {}
    for src, dst, _line, _local in imports(root):
        if dst in known and dst != src:
            edges.setdefault(src, set()).add(dst)
    return [f"import cycle: {' -> '.join(comp)}" for comp in cycles(edges)]


def addon_violations(root: Path) -> list[str]:
    """Every broken rule of the add-on at ``root`` (``.../ple_addon``), one line each: ranks, the
    features' independence, ``corelink`` as the one door into the core, no circles, module sizes."""
    known = modules(root)
    found = import_cycles(root)
    for src, dst, line, local in imports(root):
        where = f"{known[src].relative_to(root.parent)}:{line}"
        top = dst.split(".")[0]
        s, d = _short(src), _short(dst)
        if top in ("ple", "vendor") or dst.startswith(f"{root.name}.vendor"):
            if s != "corelink":
                found.append(f"{where}: {src} imports the core ({dst}): only corelink may")
            continue
        if top != root.name or dst not in known or dst == src:
            continue
        if local:
            found.append(f"{where}: function-local import of {dst}")
        if s.startswith("features.") and d.startswith("features.") and s != d:
            found.append(f"{where}: feature {src} imports the feature {dst}")
        elif d.startswith("features.") and s != "":
            found.append(f"{where}: {src} imports the feature {dst} (only the add-on's __init__ may)")
        elif s not in ADDON_RANK:
            found.append(f"{where}: {src} has no rank (give it one here and in docs/architecture.md)")
        elif d in ADDON_RANK and ADDON_RANK[d] >= ADDON_RANK[s] and not (s == "" or d.startswith(f"{s}.")):
            found.append(f"{where}: {src} imports {dst}, which is not below it")
    for path in known.values():
        n = len(path.read_text().splitlines())
        if n > MAX_LINES:
            found.append(f"{path.relative_to(root.parent)}: {n} lines (at most {MAX_LINES})")
    return found + private_crossings(root)


def test_the_addon_keeps_its_layers():
    assert addon_violations(ADDON) == []


def test_every_addon_module_has_a_rank_and_registers():
    for mod, path in modules(ADDON).items():
        if _short(mod) in ("batch", "build"):  # repository tools, not shipped in the extension
            continue
        assert _short(mod) in ADDON_RANK, f"{mod}: give it a rank in ADDON_RANK and docs/architecture.md"
        names = {n.name for n in ast.parse(path.read_text()).body if isinstance(n, ast.FunctionDef)}
        assert {"register", "unregister"} <= names, f"{mod} needs register() and unregister()"


def test_the_tools_import_no_circle():
    assert import_cycles(TOOLS) == []


@pytest.mark.parametrize("module, text, rule", [
    ("features/bad.py", "from . import clg\n", "imports the feature"),
    ("rig/bad.py", "from ..features import body\n", "only the add-on's __init__ may"),
    ("ops/bad.py", "import ple\n", "only corelink may"),
    ("draw.py", "from .rig import model\n", "not below it"),
    ("rig/model.py", "def f():\n    from . import events\n", "function-local import"),
    ("rig/model.py", "def f():\n    from . import events\n", "import cycle"),
    ("ui.py", "\n" * MAX_LINES, "lines (at most"),
    ("ops/bad.py", "from .base import _style_item\n", "private name _style_item"),
])
def test_a_forbidden_import_in_the_addon_is_caught(tmp_path, module, text, rule):
    """The checker itself: a copy of the add-on with one bad module (or line) breaks exactly that rule."""
    root = tmp_path / "ple_addon"
    shutil.copytree(ADDON, root, ignore=shutil.ignore_patterns("__pycache__"))
    path = root / module
    path.write_text((path.read_text() if path.exists() else "") + text)
    found = addon_violations(root)
    bad = module.split("/")[-1].removesuffix(".py")
    assert any(rule in v and bad in v for v in found), found
    assert all(bad in v for v in found), found  # nothing else in the copy is reported

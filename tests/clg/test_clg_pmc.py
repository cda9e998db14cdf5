"""CLG point membership (thesis §5.5, §10.2) against an independent brute-force CSG over every
primitive of every chunk copy, on random steady and BeCOTS patterns, random expressions (with
compound primitives) and recursive materials. Disagreements are allowed only within 1e-7 of a
primitive's surface."""

from __future__ import annotations

import numpy as np
import pytest
from clg_reference import inside
from ple.clg.ir import clg_from_dict
from ple.clg.query import brute_force_value, compiled

OPS = ("union", "intersection", "difference")


def random_pattern(rng, kind: str) -> dict:
    nn = int(rng.integers(1, 3))
    nodes = [{"center": list(rng.uniform(-0.3, 0.3, 3)), "radius": float(rng.uniform(0.08, 0.2))}
             for _ in range(nn)]
    beams = [{"from": 0, "to": 0, "offset": [1, 0, 0]}, {"from": 0, "to": nn - 1, "offset": [0, 1, 0]}]
    if nn > 1:
        beams.append({"from": 1, "to": 0, "offset": [0, 0, 0]})
    pat = {"format": "ple-lattice/1", "nodes": nodes, "beams": beams}
    if kind == "steady":
        pat["U"] = {"count": 3, "similarity": {"kind": "translation", "vector": [1.0, 0.1 * rng.standard_normal(), 0]}}
        pat["V"] = {"count": 3, "similarity": {"kind": "translation", "vector": [0.1, 1.0, 0.2 * rng.random()]}}
        pat["W"] = {"count": 2, "similarity": {"kind": "translation", "vector": [0, 0.1, 1.0]}}
    elif kind == "swirl":  # rotation about z and a swirl about the same axis commute
        pat["U"] = {"count": 4, "similarity": {"kind": "swirl", "angle": 0.5, "axis": [0, 0, 1], "point": [0, 0, 0],
                                               "factor": float(rng.uniform(1.05, 1.2))}}
        pat["V"] = {"count": 3, "similarity": {"kind": "screw", "angle": 0.3, "axis": [0, 0, 1], "point": [0, 0, 0],
                                               "distance": 0.0}}
        pat["placement"] = {"similarity": {"kind": "translation", "vector": [2.0, 0, 0]}}
        for n in nodes:
            n["center"][0] += 0.0
    elif kind == "warped":  # random rotations, swirls, screws and scalings about unrelated axes: no two commute
        for name, count in zip("UVW", (3, 3, 2)):
            pat[name] = {"count": count, "similarity": warped_similarity(rng)}
        if rng.random() < 0.5:
            pat["placement"] = {"similarity": {"kind": "screw", "angle": float(rng.uniform(-3, 3)),
                                               "axis": _unit(rng), "point": list(rng.normal(0, 1, 3)),
                                               "distance": float(rng.normal())}}
    else:  # a BeCOTS slab from random corners
        a = [0.0, 0.0, 0.0]
        b = [float(x) for x in [0.2, 4, 0.2] + 0.2 * rng.standard_normal(3)]
        c = [float(x) for x in [4.5, 4.5, 0.8] + 0.3 * rng.standard_normal(3)]
        d = [float(x) for x in [4, -0.2, 0.2] + 0.2 * rng.standard_normal(3)]
        pat["becots"] = {"corners": [a, b, c, d], "counts": [4, 4]}
        for n in nodes:
            n["center"] = [float(x) * 0.5 for x in n["center"]]
    return pat


def _unit(rng) -> list:
    v = rng.standard_normal(3)
    return [float(x) for x in v / np.linalg.norm(v)]


def warped_similarity(rng) -> dict:
    """A random rotation, swirl, screw or scaling about a random axis, its fixed point (or axis)
    about 1/angle (1/|log factor|) from the origin so that one step moves the template about a unit."""
    axis = np.array(_unit(rng))
    side = np.cross(axis, _unit(rng))
    side /= np.linalg.norm(side)
    angle = float(rng.uniform(0.15, 0.4) * rng.choice([-1, 1]))
    factor = float(rng.uniform(1.08, 1.2) ** rng.choice([-1, 1]))
    kind = str(rng.choice(["rotation", "swirl", "screw", "scaling"]))
    if kind == "scaling":
        return {"kind": kind, "factor": factor, "point": [float(x) for x in side / abs(np.log(factor))]}
    point = [float(x) for x in side / abs(angle)]
    if kind == "rotation":
        return {"kind": kind, "angle": angle, "axis": list(axis), "point": point}
    if kind == "swirl":
        return {"kind": kind, "angle": angle, "axis": list(axis), "point": point, "factor": factor}
    return {"kind": kind, "angle": angle, "axis": list(axis), "point": [x / 2 for x in point],
            "distance": float(rng.uniform(0.4, 0.8))}


def rand_ref(rng, nn):
    return [int(x) for x in rng.integers(-1, 2, 3)] + [int(rng.integers(0, nn))]


def random_prim(rng, nn, mat=None):
    k = rng.random()
    if k < 0.35:
        out = {"ball": {"node": rand_ref(rng, nn), "scale": float(rng.uniform(0.6, 1.6))}}
    elif k < 0.8:
        a = rand_ref(rng, nn)
        b = rand_ref(rng, nn)
        while b == a:
            b = rand_ref(rng, nn)
        out = {"beam": {"from": a, "to": b, "scale": [float(rng.uniform(0.4, 1.2)), float(rng.uniform(0.4, 1.2))]}}
    elif k < 0.88:
        a, b = rand_ref(rng, nn), [1, 0, 0, 0]
        h = float(rng.uniform(0.3, 0.8))
        out = {"hollow_beam": {"from": a[:3] + [0], "to": b, "scale": [1.0, 0.8], "hollow": h}}
        if a[:3] == [1, 0, 0]:
            out["hollow_beam"]["from"] = [0, 0, 0, 0]
    elif k < 0.94:
        out = {"extended_hub": {"node": rand_ref(rng, nn), "scale": [float(rng.uniform(0.6, 1.0)), 0.5]}}
    else:
        out = {"connector": {"node": rand_ref(rng, nn), "outer": 0.8, "inner": 0.5, "reach": 4.0}}
    if mat is not None:
        next(iter(out.values()))["material"] = mat
    return out


def random_expr(rng, nn, depth=0, mat=None):
    if depth >= 2 or rng.random() < 0.3:
        return random_prim(rng, nn, mat if rng.random() < 0.5 else None)
    op = OPS[int(rng.integers(0, 3))]
    return {op: [random_expr(rng, nn, depth + 1, mat) for _ in range(int(rng.integers(1, 4)))]}


def random_clg(rng, kind: str, mat=None) -> dict:
    pat = random_pattern(rng, kind)
    nn = len(pat["nodes"])
    chunks = {f"C{c}": random_expr(rng, nn, 0, mat) for c in range(int(rng.integers(1, 4)))}
    names = list(chunks)
    first = {"union": names[:1]} if len(names) == 1 else {OPS[int(rng.integers(0, 3))]: names}
    solid = {"union": [first, names[0]]} if rng.random() < 0.5 else first
    if rng.random() < 0.5:  # the solid's positive part must be a union of chunks sometimes
        solid = {"union": names}
    return {"format": "ple-clg/1", "pattern": pat, "chunks": chunks, "solid": solid}


def sample_points(comp, rng, q):
    lo, hi = comp.lo, comp.hi
    box = lo - 0.1 + rng.random((q // 2, 3)) * (hi - lo + 0.2)
    # points near the template nodes of random groups: many land close to surfaces
    lat = comp.lat
    m = q - q // 2
    idx = np.column_stack([rng.integers(0, c, m) for c in lat.counts] + [rng.integers(0, len(lat.nodes), m)])
    c, r = lat.node_balls(idx)
    near = c + rng.standard_normal((len(c), 3)) * r[:, None] * 1.2
    return np.concatenate([box, near])


def check(data, q, rng):
    clg = clg_from_dict(data)
    comp = compiled(clg)
    p = sample_points(comp, rng, q)
    got = comp.pmc(p)
    want = inside(data, clg, p)
    bad = got != want
    if bad.any():  # only then collect the distances to every primitive surface
        tol = []
        inside(data, clg, p[bad], tol)
        near = np.zeros(len(p), bool)
        near[bad] = np.min(np.array(tol), axis=0) < 1e-7 * max(1.0, comp.scale)
        assert np.all(near[bad]), f"{int((bad & ~near).sum())} points disagree away from surfaces"
    return got, want


@pytest.mark.parametrize("kind", ["steady", "swirl", "becots"])
@pytest.mark.parametrize("seed", range(4))
def test_pmc_matches_brute_force(kind, seed):
    rng = np.random.default_rng(100 * seed + len(kind))
    got, want = check(random_clg(rng, kind), 1500, rng)
    assert want.any() or not got.any()


@pytest.mark.parametrize("frame", ["world", "beam"])
@pytest.mark.parametrize("seed", range(3))
def test_recursive_materials_match_brute_force(frame, seed):
    rng = np.random.default_rng(7 + seed)
    data = random_clg(rng, "becots" if seed % 2 else "steady", mat="m")
    inner = random_clg(rng, "steady")  # the replacing CLG in its own frame (beam frame: unit length on x)
    if frame == "beam":
        inner["pattern"]["nodes"] = [{"center": [0.0, 0.0, 0.0], "radius": 0.12}]
        inner["pattern"]["beams"] = [{"from": 0, "to": 0, "offset": [1, 0, 0]},
                                     {"from": 0, "to": 0, "offset": [0, 1, 0]}]
        inner["pattern"]["U"] = {"count": 5, "similarity": {"kind": "translation", "vector": [0.25, 0, 0]}}
        inner["pattern"]["V"] = {"count": 3, "similarity": {"kind": "translation", "vector": [0, 0.2, 0]}}
        inner["pattern"]["W"] = {"count": 1, "similarity": {"kind": "identity"}}
        inner["pattern"]["placement"] = {"similarity": {"kind": "translation", "vector": [0, -0.2, 0]}}
        inner["chunks"] = {"A": {"union": [{"beam": {"from": [0, 0, 0, 0], "to": [1, 0, 0, 0], "scale": [1, 1]}},
                                           {"beam": {"from": [0, 0, 0, 0], "to": [0, 1, 0, 0], "scale": [1, 1]}}]}}
        inner["solid"] = "A"
    data["materials"] = {"m": {"replace": inner, "frame": frame}}
    got, want = check(data, 600, rng)
    # the replacement matters somewhere: without it, membership differs on some points
    plain = clg_from_dict(dict(data, materials={"m": {}}))
    p = sample_points(compiled(plain), np.random.default_rng(seed), 1000)
    assert (compiled(plain).pmc(p) != compiled(clg_from_dict(data)).pmc(p)).any() or not want.any()


def test_library_brute_force_agrees():
    rng = np.random.default_rng(5)
    data = random_clg(rng, "becots")
    clg = clg_from_dict(data)
    comp = compiled(clg)
    p = sample_points(comp, rng, 400)
    tol = []
    want = inside(data, clg, p, tol)
    got = brute_force_value(clg, p) <= 0
    near = np.min(np.array(tol), axis=0) < 1e-7
    assert np.all((got == want) | near)


def test_clipped_values_are_exact_clips():
    """value(P, R) = clip(f, -R, R) with f the unclipped CSG value (brute force over every copy)."""
    rng = np.random.default_rng(11)
    clg = clg_from_dict(random_clg(rng, "becots"))
    comp = compiled(clg)
    p = sample_points(comp, rng, 300)
    r = rng.uniform(0.01, 0.5, len(p))
    full = brute_force_value(clg, p)
    got = comp.value(p, r)
    np.testing.assert_allclose(got, np.clip(full, -r, r), atol=1e-12)

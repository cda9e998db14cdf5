"""Warped steady lattice: bent (U rotates), twisted (V screws) and tapered (W scales) — one ball, 3 beam-patterns."""


def lattice(n: Range(2, 200) = 20, radius: Range(0.01, 0.4) = 0.12, bend: Range(0.0, 3.0) = 1.2,
            twist: Range(0.0, 3.0) = 0.8, taper: Range(0.2, 1.0) = 0.6):
    lat = Lattice()
    a = lat.add_node(Pt(0, 0, 0), radius)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1)]:
        lat.add_beam(a, a, *off)
    span = n - 1.0
    # U: the row of length `span` bends by `bend` radians around an axis parallel to y
    if bend > 0:
        lat.set_u(n, Rotation(bend, Vec(0, -1, 0), Pt(0, 0, span / bend)), cumulative=True)
    else:
        lat.set_u(n, Translation(Vec(span, 0, 0)), cumulative=True)
    # V: along y, the slab twists by `twist` radians about its own centre line
    lat.set_v(n, Screw(twist, Vec(0, 1, 0), Pt(span / 2, 0, span / 2), span), cumulative=True)
    # W: layers step toward a far fixed point, shrinking to `taper` of their size
    if taper < 1:
        far = span / (1 - taper)
        lat.set_w(n, Scaling(taper, Pt(span / 2, span / 2, far)), cumulative=True)
    else:
        lat.set_w(n, Translation(Vec(0, 0, span)), cumulative=True)
    return lat

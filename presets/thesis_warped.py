"""Thesis warped lattice (§7.4, Fig. 7.10): 100³ groups of one ball and 3 beam-patterns, bent, twisted and tapered."""


def lattice(n: Range(2, 200) = 100, radius: Range(0.01, 0.4) = 0.12, bend: Range(0.1, 3.0) = 1.2,
            twist: Range(0.1, 3.0) = 0.8, taper: Range(0.2, 0.99) = 0.6):
    lat = Lattice()
    a = lat.add_node(Pt(0, 0, 0), radius)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1)]:
        lat.add_beam(a, a, *off)
    span = n - 1.0
    # bent: the U row of length `span` turns by `bend` radians about an axis parallel to y
    lat.set_u(n, Rotation(bend, Vec(0, -1, 0), Pt(0, 0, span / bend)), cumulative=True)
    # twisted: along y the slab screws by `twist` radians about its centre line
    lat.set_v(n, Screw(twist, Vec(0, 1, 0), Pt(span / 2, 0, span / 2), span), cumulative=True)
    # tapered: layers step toward a far fixed point, shrinking to `taper` of their size
    lat.set_w(n, Scaling(taper, Pt(span / 2, span / 2, span / (1 - taper))), cumulative=True)
    return lat

"""Stencil hierarchy: a fine cubic lattice whose groups are kept on the edges of a period-6 coarse frame."""


def lattice(n: Range(6, 120) = 37, radius: Range(0.02, 0.3) = 0.12, period: Range(2, 16) = 6,
            width: Range(1, 4) = 1, pattern: str = "edges"):
    lat = Lattice()
    a = lat.add_node(Pt(0, 0, 0), radius)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1)]:
        lat.add_beam(a, a, *off)
    lat.set_u(n, Translation(Vec(1, 0, 0)))
    lat.set_v(n, Translation(Vec(0, 1, 0)))
    lat.set_w(n, Translation(Vec(0, 0, 1)))
    lat.set_filter(Stencil.named(pattern, period, width))
    return lat

"""Gyroid-filtered octet-like cubic lattice: fine nodes kept inside the network of a gyroid (graded cells)."""


def lattice(n: Range(4, 80) = 30, radius: Range(0.02, 0.3) = 0.1, cell: Range(2.0, 40.0) = 15.0,
            level: Range(-1.0, 1.0) = -0.5, sheet: bool = False):
    lat = Lattice()
    a = lat.add_node(Pt(0, 0, 0), radius)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (0, 1, 1), (1, 0, 1)]:
        lat.add_beam(a, a, *off)
    lat.set_u(n, Translation(Vec(1, 0, 0)))
    lat.set_v(n, Translation(Vec(0, 1, 0)))
    lat.set_w(n, Translation(Vec(0, 0, 1)))
    # shift the field so that the lattice's corner sits in the middle of a gyroid channel
    # (a gyroid minimum lies at (1/8, 3/8, 5/8) of the cell)
    field = TPMSField("gyroid", cell, Translation(Vec(-cell / 8, -3 * cell / 8, -5 * cell / 8)))
    lat.set_filter(ImplicitFilter(field, level if not sheet else abs(level) + 0.3, "sheet" if sheet else "network"))
    return lat

"""Möbius steady slab (thesis §11.3, Fig. 11.5): three Möbius frames place the template; rows bend into circles."""


def lattice(nu: Range(1, 60) = 10, nv: Range(1, 60) = 6, radius: Range(0.01, 0.3) = 0.08,
            bend: Range(0.0, 0.3) = 0.08):
    # frame X = identity; Y = X moved one cell along x and bent; Z = X moved one cell along y
    x = (Pt(0, 0, 0), Pt(1, 0, 0), Pt(0, 1, 0))
    y = (Pt(1, 0, 0), Pt(2, bend, 0), Pt(1 - bend, 1, 0))
    z = (Pt(0, 1, 0), Pt(1, 1 + bend, 0), Pt(0, 2, 0))
    cell = Lattice()
    a = cell.add_node(Pt(0, 0, 0), radius)
    b = cell.add_node(Pt(0.5, 0.5, 0), radius * 0.8)
    for off in ((1, 0), (0, 1)):
        cell.add_beam(a, a, *off)
    cell.add_beam(a, b)
    cell.add_beam(b, a, 1, 1)
    cell.add_beam(b, a, 1, 0)
    cell.add_beam(b, a, 0, 1)
    return mobius_frames_lattice(cell, x, y, z, (nu, nv))

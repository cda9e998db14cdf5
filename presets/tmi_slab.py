"""TMI slab (thesis §11.4, Fig. 11.6): a Trans-Möbius Interpolant of five points; nodes are exact Möbius images."""


def lattice(nu: Range(1, 60) = 8, nv: Range(1, 60) = 8, radius: Range(0.01, 0.4) = 0.12,
            bulge: Range(-1.5, 1.5) = -0.6):
    # M(0,0)=A, M(1,0)=B, M(0,1)=C, M(1,1)=D and the mid-edge point M(.5,0)=E (§11.4.2)
    tmi = TMIMap.from_five(Pt(0, 0, 0), Pt(4, 0, 0), Pt(0.5, 4, 0), Pt(4.5, 5, 0), Pt(2, bulge, 0))
    cell = Lattice()
    a = cell.add_node(Pt(0, 0, 0), radius)
    cell.add_beam(a, a, 1, 0, 0)
    cell.add_beam(a, a, 0, 1, 0)
    return tmi.lattice(cell, (nu, nv))

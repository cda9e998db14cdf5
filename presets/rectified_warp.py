"""Rectified steady warp (thesis §3.1–3.4, Fig. 3.2): a regular slab bent, tapered and twisted, nodes rectified."""


def lattice(nu: Range(2, 200) = 12, nv: Range(2, 200) = 8, radius: Range(0.02, 0.4) = 0.14,
            bend: Range(0.0, 3.0) = 1.2, taper: Range(0.3, 1.0) = 0.6, twist: Range(0.0, 2.0) = 0.5):
    # the regular slab in cell units: a square grid with a raised centre node per cell
    cell = Lattice()
    a = cell.add_node(Pt(0, 0, 0), radius)
    b = cell.add_node(Pt(0.5, 0.5, 0.4), radius * 0.8)
    cell.add_beam(a, a, 1, 0, 0)
    cell.add_beam(a, a, 0, 1, 0)
    for di, dj in ((0, 0), (1, 0), (0, 1), (1, 1)):
        cell.add_beam(b, a, di, dj, 0)
    # M(u, v) = V**v ∘ U**u (O): U bends the whole length and tapers it, V screws across it
    far = nu / max(bend, 1e-9)
    if bend > 0:
        u = Swirl(bend, Vec(0, 0, 1), Pt(0, far, 0), taper)
    else:  # straight: O moves nu along x while the slab tapers
        u = Scaling(taper, Pt(nu / (1 - taper), 0, 0)) if taper < 1 else Translation(Vec(nu, 0, 0))
    v = Screw(twist, Vec(0, 1, 0), Pt(0, 0, 0), nv)
    return rectified_warp(cell, u, v, None, Pt(0, 0, 0), (nu, nv))

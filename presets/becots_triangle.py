"""BeCOTS triangle lattice (Fig. 4.13c): 6 beams per inner hub; levels > 1 filters it into a multi-level structure."""


def lattice(nu: Range(2, 400) = 12, nv: Range(2, 400) = 12, radius: Range(0.01, 0.3) = 0.08,
            lift: Range(-2.0, 2.0) = 0.8, levels: Range(1, 4) = 1):
    # corners A=M(0,0), B=M(0,1), C=M(1,1), D=M(1,0); lifting C bends the slab onto a cone
    field = BeCOTSField.from_corners(Pt(0, 0, 0), Pt(0.3, 4, 0.3), Pt(5, 5, lift), Pt(4.5, -0.3, 0.2))
    period = int(levels)
    n_u, n_v = (int(nu) // period) * period, (int(nv) // period) * period
    return becots_lattice(field, (n_u, n_v), "triangle", radius, period=period)

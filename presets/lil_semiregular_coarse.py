"""LiL coarse (thesis Fig. 7.9): semi-regular n³ frame turned about z and twisted (screw W), 1 ball, 3 beam-patterns."""


def lattice(n: Range(2, 50) = 8, span: Range(1, 500) = 63.0, radius: Range(0.01, 0.45) = 0.12,
            turn: Range(0.0, 1.6) = 0.5, twist: Range(0.0, 1.6) = 0.6):
    lat = Lattice()
    cell = span / (n - 1)
    a = lat.add_node(Pt(0, 0, 0), radius * cell)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1)]:
        lat.add_beam(a, a, *off)
    centre = Pt(span / 2, span / 2, 0)
    lat.set_u(n, Translation(Vec(cell, 0, 0)))
    lat.set_v(n, Translation(Vec(0, cell, 0)))
    # W climbs one cell and turns about the vertical axis through the middle: `twist` radians in all
    lat.set_w(n, Screw(twist / (n - 1), Vec(0, 0, 1), centre, cell))
    lat.set_placement(Rotation(turn, Vec(0, 0, 1), centre))
    return lat

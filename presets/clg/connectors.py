"""Beam connectors holding rods (thesis §5.4.2, Fig. 5.3-5.4) on a bent BeCOTS slab."""


def clg(nu: Range(2, 100) = 6, nv: Range(2, 100) = 6, rods: Range(0, 1) = 1, reach: Range(1.5, 6.0) = 3.0):
    lat = Lattice()
    n = lat.add_node(Pt(0, 0, 0), 0.1, "n")
    lat.add_beam(n, n, 1, 0, 0)
    lat.add_beam(n, n, 0, 1, 0)
    field = BeCOTSField.from_corners(Pt(0, 0, 0), Pt(0.2, 4, 0.3), Pt(4.5, 4.5, 1.2), Pt(4, -0.2, 0.2))
    lat.set_field(field, (int(nu), int(nv)))
    chunks = {"connectors": Connector((0, 0, 0, "n"), outer=1.5, inner=1.0, reach=reach)}
    solid = Chunk("connectors")
    if int(rods):  # the rods the connectors hold: thinner than the hollow, shorter than the beams
        chunks["rods"] = Union(Beam((0, 0, 0, "n"), (1, 0, 0, "n"), (0.9, 0.9)),
                               Beam((0, 0, 0, "n"), (0, 1, 0, "n"), (0.9, 0.9)))
        solid = Union(Chunk("connectors"), Chunk("rods"))
    return CLG(lat, chunks, solid)

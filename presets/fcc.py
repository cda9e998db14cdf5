"""Face-centred cubic: corner ball and three face-centre balls, each face centre joined to its four corners."""


def lattice(n: Range(1, 100) = 6, cell: Range(0.1, 10) = 1.0, radius: Range(0.01, 0.2) = 0.06):
    lat = Lattice()
    h = cell / 2
    c = lat.add_node(Pt(0, 0, 0), radius * cell, "corner")
    faces = {"xy": (Pt(h, h, 0), [(0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0)]),
             "yz": (Pt(0, h, h), [(0, 0, 0), (0, 1, 0), (0, 0, 1), (0, 1, 1)]),
             "zx": (Pt(h, 0, h), [(0, 0, 0), (1, 0, 0), (0, 0, 1), (1, 0, 1)])}
    for name, (centre, corners) in faces.items():
        f = lat.add_node(centre, radius * cell, name)
        for off in corners:
            lat.add_beam(f, c, *off)
    lat.set_u(n, Translation(Vec(cell, 0, 0)))
    lat.set_v(n, Translation(Vec(0, cell, 0)))
    lat.set_w(n, Translation(Vec(0, 0, cell)))
    return lat

"""Octet truss: FCC nodes with all 12 nearest-neighbour struts per node (stretch-dominated)."""


def lattice(n: Range(1, 100) = 5, cell: Range(0.1, 10) = 1.0, radius: Range(0.01, 0.15) = 0.05):
    lat = Lattice()
    h = cell / 2
    # four FCC sites per cubic cell; every pair at distance cell/sqrt(2) is a strut
    sites = {"o": (0, 0, 0), "xy": (h, h, 0), "yz": (0, h, h), "zx": (h, 0, h)}
    ids = {name: lat.add_node(Pt(*p), radius * cell, name) for name, p in sites.items()}
    target = cell / 2 ** 0.5
    for a, pa in sites.items():
        for b, pb in sites.items():
            for di in (-1, 0, 1):
                for dj in (-1, 0, 1):
                    for dk in (-1, 0, 1):
                        q = (pb[0] + di * cell, pb[1] + dj * cell, pb[2] + dk * cell)
                        d = sum((x - y) ** 2 for x, y in zip(q, pa)) ** 0.5
                        if abs(d - target) > 1e-9:
                            continue
                        # keep each strut once: the lexicographically positive direction
                        key = (di, dj, dk, list(sites).index(b) - list(sites).index(a))
                        if key > (0, 0, 0, 0):
                            lat.add_beam(ids[a], ids[b], di, dj, dk)
    lat.set_u(n, Translation(Vec(cell, 0, 0)))
    lat.set_v(n, Translation(Vec(0, cell, 0)))
    lat.set_w(n, Translation(Vec(0, 0, cell)))
    return lat

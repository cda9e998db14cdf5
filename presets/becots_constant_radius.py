"""Constant-radius BeCOTS honeycomb (§4.5.3): export congruent connectors with `ple becots connectors`."""


def lattice(nu: Range(2, 100) = 8, nv: Range(2, 100) = 8, radius: Range(0.01, 0.3) = 0.05):
    field = BeCOTSField.from_corners(Pt(0, 0, 0), Pt(0, 6, 1), Pt(7, 7, 3.5), Pt(6, 0, 1.2))
    return becots_lattice(field, (nu, nv), "honeycomb", radius)

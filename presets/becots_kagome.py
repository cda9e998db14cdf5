"""BeCOTS Kagome (Fig. 4.12): a planar COTS Kagome raised off its plane, 4 beams per inner hub."""


def lattice(nu: Range(2, 400) = 10, nv: Range(2, 400) = 10, radius: Range(0.01, 0.3) = 0.06,
            height: Range(-3.0, 3.0) = 1.5):
    # a planar COTS from four coplanar corners, then Raise(height) (§4.3.1)
    cots = BeCOTSField.from_corners(Pt(0, 0, 0), Pt(-0.5, 4, 0), Pt(4.5, 6, 0), Pt(5, 0.5, 0))
    return becots_lattice(cots.raised(height), (nu, nv), "kagome", radius)

"""BeCOTS stack (§6.3): bent triangle layers by constant-distance raise or normal offset, joined by beams."""


def lattice(nu: Range(2, 200) = 10, nv: Range(2, 200) = 10, layers: Range(1, 50) = 4,
            spacing: Range(0.05, 2.0) = 0.5, mode: str = "raise", radius: Range(0.01, 0.3) = 0.07):
    field = BeCOTSField.from_corners(Pt(0, 0, 0), Pt(0, 4, 0.4), Pt(4.6, 4.4, 1.4), Pt(4, 0, 0.3))
    # links (n1, n2, di, dj): each node to the node above it and to its +u neighbour above
    return stack_lattice(field, (nu, nv), layers, spacing, mode, "triangle", radius,
                         links=((0, 0, 0, 0), (0, 0, 1, 0)))

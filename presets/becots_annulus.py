"""Seamless BeCOTS annulus (§4.4.3): V is one full turn, so the map closes into a ring with two border loops.

A ring-closing beam-pattern joins the seam."""


def lattice(nu: Range(2, 200) = 8, nv: Range(3, 400) = 36, radius: Range(0.01, 0.3) = 0.12,
            growth: Range(0.1, 2.0) = 0.9, twist: Range(-2.0, 2.0) = 0.5, beta: Range(0.2, 1.5707963) = 1.2):
    # U grows and twists, V = one full turn on the cone (ln m_v = 0; the flat angle 2π sin β becomes
    # 2π once bent, Eq. 4.5); corners A = B and D = C coincide, so the field comes from its controls
    field = BeCOTSField.from_controls((growth, twist, 0.0, 2 * pi * math.sin(beta)), beta=beta)
    lat = Lattice()
    a = lat.add_node(Pt(1, 0, 0), radius, "a")
    lat.add_beam(a, a, 1, 0, 0)
    lat.add_beam(a, a, 0, 1, 0)
    lat.add_beam(a, a, 1, 1, 0)
    lat.add_beam(a, a, 0, 1 - nv, 0)  # ring-closing: group (i, nv-1) to (i, 0)
    lat.add_beam(a, a, 1, 1 - nv, 0)  # ring-closing diagonal: (i, nv-1) to (i+1, 0)
    set_field(lat, field, (nu, nv))
    return lat

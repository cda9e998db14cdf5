"""BeCOTS honeycomb (Fig. 4.13a): 2 node-patterns, 3 beam-patterns, bent onto a cone of half-angle beta."""


def lattice(nu: Range(2, 400) = 12, nv: Range(2, 400) = 16, radius: Range(0.01, 0.3) = 0.06,
            beta: Range(0.2, 1.5707963) = 0.9, growth: Range(-1.0, 1.0) = 0.6, turn: Range(0.0, 3.0) = 1.6):
    # warp (ln m_u, w_u, ln m_v, w_v), bend beta, unit placement (§4.3.3)
    field = BeCOTSField.from_controls((growth, 0.15, 0.05, turn), beta=beta)
    return becots_lattice(field, (nu, nv), "honeycomb", radius)

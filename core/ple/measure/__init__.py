"""Layer 5 — integral properties of lattices (thesis §3.6–3.7, §6.1.4): area and volume by exact
hub measures and closed-form series."""

"""Layer 3 — questions asked of a lattice without evaluating it: the RangeFinder (thesis §7), the BeCOTS
RangeFinder (§8), the BIQ/PMC/distance dispatcher, and a grid over explicit elements."""

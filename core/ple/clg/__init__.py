"""Layer 4½ — Constructive Lattice Geometry (thesis §5, §10): chunks, Boolean expressions of chunk
unions, compound primitives, recursive materials; the ``ple-clg/1`` description; PMC, distances,
voxels, slices and rays that visit only the chunk copies a query can touch."""

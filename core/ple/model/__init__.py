"""Layer 2 — what a lattice is: template node-group, beam-patterns, U, V, W and counts, lazy evaluation
of regions; the ``ple-lattice/1`` description; BeCOTS fields and lattices; the cage."""

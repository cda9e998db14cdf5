"""Layer 6 — files: atomic writes, the mesh-format registry, mesh/3MF writers, ``ple-lattice/1``
files, streamed chunk folders."""

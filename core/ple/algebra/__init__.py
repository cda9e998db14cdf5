"""Layer 1 — the mathematics: points and vectors, frames, similarities and their real powers, geometric
series, exact ball and cone-beam distances. Imports nothing of PLE but ``errors``."""

"""Layer 8 — jobs built from the layers below: batch sweeps and progress reporting."""

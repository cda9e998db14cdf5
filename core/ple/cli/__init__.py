"""Layer 9 — the ``ple`` command line: one module per sub-command, each a thin door onto the layers below."""

"""Layer 7 — lattice programs (SPEC §4): running them with the API in scope, the preset library,
sources (program, IR file or preset), and snippets that edit program text."""

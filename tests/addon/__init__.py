"""The Blender extension's tests (a package, so that its conftest does not shadow the core tests' own)."""

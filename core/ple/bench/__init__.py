"""Benchmarks for ``ple bench NAME``: each module has ``add_arguments(parser)`` and
``run(args) -> dict`` (JSON-able, with a baseline measured in the same run)."""

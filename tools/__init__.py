"""Repository tools, not part of the library or the extension: the demo, the docs builder and the
renderers of their pictures (``python -m tools.demo``, ``python -m tools.docs_build``)."""

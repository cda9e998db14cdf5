"""The add-on's features: the Body panel (``body``), CLG rigs (``clg``), Möbius rigs (``mobius``) and
the Check panel (``check``). Each holds its properties, operators, panel and hooks, depends only on
the rig, the operator bases and the drawing (and the layers below them), and plugs into the rig
through ``rig.hooks`` in its ``register()``. Features never import each other; only the add-on's
``__init__`` imports them."""

from __future__ import annotations


def register() -> None:
    pass  # the add-on's __init__ registers each feature (this package imports none of them)


def unregister() -> None:
    pass

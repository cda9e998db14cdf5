"""The add-on's operators, grouped by job: ``base`` (what they share), ``program``, ``template``
(template and filters) and ``output`` (meshes and files)."""

from __future__ import annotations

from . import base, output, program, template

MODULES = (base, program, template, output)


def register() -> None:
    for m in MODULES:
        m.register()


def unregister() -> None:
    for m in reversed(MODULES):
        m.unregister()

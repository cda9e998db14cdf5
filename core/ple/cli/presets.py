"""``ple presets``: list the presets with one-line descriptions."""

from __future__ import annotations

from ..program.presets import preset_description, preset_names


def register(sub) -> None:
    p = sub.add_parser("presets", help="list presets with one-line descriptions")
    p.set_defaults(func=run)


def run(args) -> int:
    names = preset_names()
    width = max(len(n) for n in names)
    for name in names:
        print(f"{name:<{width}}  {preset_description(name)}")
    return 0

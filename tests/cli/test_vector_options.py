"""Options whose value may start with a minus sign: vector options in the space form
(``--bounds -0.5,-0.5,-0.5,0.5,0.5,0.5``), over every option of every command (``ple.cli.main.Parser``)."""

from __future__ import annotations

import argparse

import numpy as np
import pytest
from ple.cli.main import build_parser, command_names, main

# the options that take numbers separated by commas (or a region, whose indices may be negative)
VECTOR_OPTIONS = {"--bounds", "--view", "--size", "--grid", "--branch", "--corners", "--region", "--orders",
                  "--counts", "--render-size"}


def _parsers():
    """(argv prefix, parser) of every command and sub-command, nested ones included."""
    stack = [([name], build_parser(name)._subparsers._group_actions[0].choices[name]) for name in command_names()]
    while stack:
        path, parser = stack.pop()
        yield path, parser
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                stack.extend((path + [sub], p) for sub, p in action.choices.items())


def _filler(action) -> str:
    if action.choices:
        return str(next(iter(action.choices)))
    return "1" if action.type in (int, float) else "x"


def _value_options():
    """(argv prefix with every required argument filled, action) of every option that takes one value."""
    out = []
    for path, parser in _parsers():
        if any(isinstance(a, argparse._SubParsersAction) for a in parser._actions):
            continue  # its sub-commands are visited
        base = list(path)
        for a in parser._actions:
            if not a.option_strings:
                base.append(_filler(a))
            elif a.required:
                base += [a.option_strings[-1], _filler(a)]
        for a in parser._actions:
            if a.option_strings and a.nargs is None and not a.choices and not isinstance(
                    a, (argparse._StoreConstAction, argparse._HelpAction, argparse._VersionAction)):
                out.append((base, a))
    return out


VALUE_OPTIONS = _value_options()


def test_every_vector_option_is_visited():
    seen = {s for _, a in VALUE_OPTIONS for s in a.option_strings}
    assert VECTOR_OPTIONS <= seen


@pytest.mark.parametrize("base,action", VALUE_OPTIONS,
                         ids=[" ".join(b[:2]) + " " + a.option_strings[-1] for b, a in VALUE_OPTIONS])
def test_option_takes_a_value_with_a_negative_first_number(base, action):
    value = "-1" if action.type in (int, float) else "-0.5,-0.5,-0.5,0.5,0.5,0.5"
    parser = build_parser(base[0])
    ns = parser.parse_args(base + [action.option_strings[-1], value])
    got = getattr(ns, action.dest)
    want = action.type(value) if action.type in (int, float) else value
    assert (got[-1] if isinstance(got, list) else got) == want


def test_clg_voxelize_takes_negative_bounds_in_the_space_form(tmp_path, capsys):
    """The report: ``--bounds=…`` worked, ``--bounds …`` was taken for an option."""
    outs = []
    for form in (["--bounds", "-0.5,-0.5,-0.5,0.5,0.5,0.5"], ["--bounds=-0.5,-0.5,-0.5,0.5,0.5,0.5"]):
        out = tmp_path / f"v{len(outs)}.npy"
        assert main(["clg", "voxelize", "plate", "--grid", "3,3,3", *form, "--out", str(out)]) == 0
        outs.append(np.load(out))
    assert np.array_equal(outs[0], outs[1])


def test_negative_region_index_in_the_space_form(tmp_path):
    out = tmp_path / "e.npz"
    assert main(["eval", "cubic", "--region", "-2:,0:1,0:1", "--out", str(out)]) == 0
    with np.load(out) as z:
        assert sorted(set(z["node_index"][:, 0].tolist())) == [8, 9]


def test_an_unknown_option_is_still_refused(capsys):
    with pytest.raises(SystemExit):
        main(["eval", "cubic", "--bogus", "1"])
    with pytest.raises(SystemExit):
        main(["eval", "cubic", "-x"])

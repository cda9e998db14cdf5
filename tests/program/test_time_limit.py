"""ple.program.runtime.time_limit: a program that runs too long stops with a PleError; only the
program's own frames are traced."""

from __future__ import annotations

import sys

import pytest
from ple.errors import PleError
from ple.program.presets import preset_path
from ple.program.runtime import ProgramTimeoutError, compile_program, time_limit


def test_time_limit_stops_a_loop_and_restores_tracing():
    prog = compile_program("def lattice():\n    while True:\n        pass\n", "loop.py")
    before = sys.gettrace()
    with pytest.raises(PleError, match="loop.py: stopped after the time limit of 0.2 s"):
        with time_limit(0.2, "loop.py"):
            prog.run()
    assert sys.gettrace() is before
    assert issubclass(ProgramTimeoutError, PleError)
    cubic = compile_program(preset_path("cubic").read_text(), "cubic.py")
    with time_limit(30.0, "cubic.py"):  # an ordinary program is unaffected
        assert cubic.run().counts == (10, 10, 10)
    with time_limit(0.2, "another.py"):  # only the named program's frames are limited
        assert cubic.run().counts == (10, 10, 10)
    with time_limit(None, "loop.py"):  # no limit
        assert cubic.run().counts == (10, 10, 10)

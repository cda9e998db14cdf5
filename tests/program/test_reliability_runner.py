"""Contained programs (ple.program.runner, issue 20): time and memory limits, exits and crashes as one
error naming the program file and line, filters surviving the trip back from the child."""

from __future__ import annotations

import json
import os
import pickle

import numpy as np
import pytest
from ple.cli.main import main
from ple.errors import PleError
from ple.program.runner import _SafeUnpickler, run_program
from ple.program.sources import load_lattice
from reliability_helpers import PEAK_LIMIT_BYTES, assert_clean_failure, ple

GOOD = ("def lattice(n=3):\n    lat = Lattice()\n    lat.add_node(Pt(0, 0, 0), 0.1)\n"
        "    lat.set_u(n, Translation(Vec(1, 0, 0)))\n    return lat\n")


def program(tmp_path, body: str, name="p.py") -> str:
    path = tmp_path / name
    path.write_text(body)
    return str(path)


@pytest.mark.parametrize("body, needle", [
    ("import sys\ndef lattice():\n    sys.exit(0)\n", "p.py:3: the program called sys.exit(0)"),
    ("import sys\ndef lattice():\n    x = 1\n    sys.exit('bye')\n", "p.py:4: the program called sys.exit('bye')"),
    ("import os\ndef lattice():\n    os._exit(3)\n", "p.py:3: the program called os._exit(3)"),
    ("def lattice():\n    raise GeneratorExit('g')\n", "p.py:2: program raised GeneratorExit: g"),
    ("def lattice():\n    raise KeyboardInterrupt\n", "p.py:2: program raised KeyboardInterrupt"),
    ("class Odd(BaseException):\n    pass\ndef lattice():\n    raise Odd('x')\n", "p.py:4: program raised Odd: x"),
    ("def lattice():\n    return lattice()\n", "p.py:2: program raised RecursionError"),
    ("def lattice():\n    return 7\n", "must return a Lattice"),
    ("def lattice():\n    lat = Lattice()\n    lat.add_node(Pt(0, 0, 0), 0.1)\n    lat.meta['f'] = lambda: 1\n"
     "    return lat\n", "cannot be returned"),
    ("import os, signal\ndef lattice():\n    os.kill(os.getpid(), signal.SIGSEGV)\n", "crashed with SIGSEGV"),
    ("import sys\nsys.exit(1)\n", "p.py:2: the program called sys.exit(1)"),
])
def test_exits_and_crashes_are_one_clear_error(tmp_path, capsys, body, needle):
    assert main(["info", program(tmp_path, body)]) == 2
    err = capsys.readouterr().err
    assert needle in err and len(err.strip().splitlines()) == 1, err


def test_endless_program_hits_the_time_limit(tmp_path, capsys):
    src = program(tmp_path, "def lattice():\n    while True:\n        pass\n")
    assert main(["info", src, "--timeout", "0.5"]) == 2
    assert "ran longer than 0.5 s; raise the limit with --timeout" in capsys.readouterr().err
    assert main(["info", src, "--timeout", "-1"]) == 2


def test_memory_hog_hits_the_memory_limit_under_the_watchdog(tmp_path):
    src = program(tmp_path, "def lattice():\n    b = bytearray(20 * 2**30)\n    return b\n")
    run = ple("info", src, "--max-memory", "1G")
    assert_clean_failure(run, "p.py:2: the program ran out of memory", "--max-memory")
    assert run.peak_rss < PEAK_LIMIT_BYTES
    run = ple("info", src, env={"PLE_MAX_MEMORY": "1G"})
    assert_clean_failure(run, "out of memory")


def test_parameters_and_errors_cross_the_process_boundary(tmp_path):
    src = program(tmp_path, GOOD)
    assert run_program(src, ["n=5"]).counts == (5, 1, 1)
    assert run_program(src, {"n": 4}).counts == (4, 1, 1)
    with pytest.raises(PleError, match="unknown parameter"):
        run_program(src, ["m=5"])


@pytest.mark.parametrize("preset", ["hier_stencil", "hier_gyroid", "hier_lil2", "becots_stack"])
def test_contained_lattices_equal_in_process_ones_filters_included(preset):
    inside, outside = load_lattice(preset), run_program(preset)
    assert type(outside.filter) is type(inside.filter)
    region = inside.region("0:3,0:3,0:3") if min(inside.counts) >= 3 else inside.region()
    a, b = inside.evaluate(region), outside.evaluate(region)  # evaluate applies the lattice's own filter
    for key, value in a.arrays().items():
        assert np.array_equal(value, b.arrays()[key]), key
    assert (outside.becots is None) == (inside.becots is None)


def test_result_unpickler_constructs_nothing_outside_the_allowlist():
    import io

    evil = pickle.dumps(("ok", os.system))
    with pytest.raises(pickle.UnpicklingError, match="posix.system|os.system"):
        _SafeUnpickler(io.BytesIO(evil)).load()
    fine = pickle.dumps(("ok", load_lattice("cubic")))
    assert _SafeUnpickler(io.BytesIO(fine)).load()[1].counts == (10, 10, 10)


def test_os_exit_under_batch_is_a_failed_variant(tmp_path, capsys):
    src = program(tmp_path, "import os\n" + GOOD.replace("def lattice(n=3):\n", "def lattice(n=3):\n"
                                                         "    if n == 2:\n        os._exit(0)\n"))
    out = tmp_path / "out"
    assert main(["batch", src, "--param", "n=2,3", "--style", "balls-beams", "--out", str(out), "--jobs", "1"]) == 2
    result = json.loads(capsys.readouterr().out)
    assert result["written"] == 1 and "os._exit(0)" in result["failed"][0]["error"]
    assert sorted(p.name for p in out.iterdir()) == [".ple-output.json", "manifest.json", "p__n-3.stl"]

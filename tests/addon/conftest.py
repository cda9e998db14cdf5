"""The add-on's tests share one headless Blender per test run: the zip is built once (offline: the
wheels come from ``build/wheels``, filled by ``make wheels``) and installed once into a worker
process (``blender_worker.py``) that runs the cases one after the other, each from a clean state.
Under xdist (``make test``: ``-n 2 --dist loadfile``) each test process that runs add-on test
files has a worker of its own, kept from one add-on file to the next (the files are collected
first, one after the other). A case whose point is a fresh start runs in a process of its own
(``fresh=True``)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(HERE))  # the case modules import each other by name (as the Blender worker does)
from blender_worker import Worker, run_fresh  # noqa: E402


def pytest_configure(config):
    config.addinivalue_line("markers", "blender: runs in the test run's headless Blender worker (tests/addon)")
    config.addinivalue_line("markers", "e2e: end to end through the command line and Dask worker processes, "
                                       "each starting Blender itself (tests/addon/test_batch_blender.py)")
    config.addinivalue_line("markers", "bpy_only: runs in a Blender whose Python has only its own packages "
                                       "(make test-blender; tests/addon/test_bpy_only.py)")


def pytest_collection_modifyitems(items):
    for item in items:
        if "run_case" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.blender)


@pytest.fixture(scope="session")
def zip_path(tmp_path_factory) -> Path:
    """The extension's zip, built once per test run (no network: wheels from ``build/wheels``)."""
    tmp = tmp_path_factory.mktemp("addon")
    # the tool run as a script: ``-m ple_addon.build`` would first import the add-on and bpy
    build = subprocess.run([sys.executable, str(ROOT / "ple_addon" / "build.py"), "--out", str(tmp)], cwd=ROOT,
                           capture_output=True, text=True)
    assert build.returncode == 0, build.stdout + build.stderr
    path = Path(build.stdout.strip().splitlines()[-1])
    assert path.name.startswith("ple-0.1.0-") and path.suffix == ".zip" and path.is_file()  # this platform's
    return path


_workers: list = []  # the session's Blender worker, stopped after the last add-on test


@pytest.fixture(scope="session")
def blender(zip_path):
    worker = Worker(zip_path)
    _workers.append(worker)
    yield worker
    worker.stop()


def pytest_runtest_teardown(item, nextitem):
    """The Blender worker is not kept idle through the rest of the run (the core's tests)."""
    if _workers and (nextitem is None or Path(str(nextitem.fspath)).parent != HERE):
        for worker in _workers:
            worker.stop()


@pytest.fixture
def run_case(request, tmp_path, zip_path):
    """``run_case(__file__, "name")`` runs ``case_name`` of that test module in the shared Blender
    (``fresh=True``: in a fresh Blender process of its own) and fails with the case's output."""

    def run(module_file: str, case: str, fresh: bool = False) -> None:
        if fresh:
            ok, log = run_fresh(zip_path, module_file, case, tmp_path)
        else:
            ok, log = request.getfixturevalue("blender").run(module_file, case, tmp_path)
        assert ok, log[-8000:]

    return run

"""One headless Blender (the bpy 5.0.1 module) that installs the extension's zip once and then runs
add-on test cases one after the other, each from a clean state.

Worker side (``python tests/addon/blender_worker.py ZIP``): installs and enables the zip, then
reads one JSON request per line on stdin — ``{"module": "test_addon_live", "case": "bake",
"cwd": DIR}`` — resets Blender (an empty scene through ``wm.read_homefile``, the add-on's
preferences back to their defaults, its session forgotten), runs ``case_<case>()`` of that test
module and answers with one line ``@@PLE-CASE@@ {"ok": ..., "error": ...}`` on stdout. With
``--once MODULE CASE`` it runs one case in this fresh process and exits (for the few cases whose
point is a fresh start).

Client side (``Worker``, used by ``conftest.py``): starts the worker, sends requests, reads the
answers with a time limit; a worker that crashed or hung is killed and started again for the
next case, so one crash costs only its own case.
"""

from __future__ import annotations

import json
import os
import queue
import subprocess
import sys
import tempfile
import threading
import traceback
from pathlib import Path

HERE = Path(__file__).resolve().parent
MARK = "@@PLE-CASE@@ "
ADDON = "bl_ext.user_default.ple"
CORE_MODULES = ("algebra.precision", "algebra.similarity", "filters", "filters.body", "filters.cleanup",
                "io.bodyfile", "io.irfile", "meshing.preview", "meshing.styles", "meshing.tessellate", "model.budget",
                "model.cage", "model.ir", "program.presets", "program.runtime", "program.snippets",
                "program.sources")  # the environment's core: the truth the cases compare with


# ----- client (pytest side) ---------------------------------------------------------------------------
class Worker:
    """A Blender worker process running cases on request (started again after a crash or hang)."""

    def __init__(self, zip_path: Path, timeout: float = 600.0, python: str = sys.executable, env: dict | None = None):
        """``python`` runs the worker (another one: a Blender with only its own packages), with
        ``env`` (default: this process's environment)."""
        self.zip_path, self.timeout, self.python, self.env = zip_path, timeout, python, env
        self.proc = None
        self.lines: queue.Queue = queue.Queue()
        self.installs = 0  # how many times the zip was installed (a restart installs it again)

    def _start(self) -> None:
        env = dict(os.environ if self.env is None else self.env,
                   BLENDER_USER_RESOURCES=tempfile.mkdtemp(prefix="ple-blender-"))
        self.proc = subprocess.Popen([self.python, str(HERE / "blender_worker.py"), str(self.zip_path)],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                     text=True, env=env, cwd=tempfile.gettempdir())
        self.lines = queue.Queue()
        threading.Thread(target=self._read, args=(self.proc, self.lines), daemon=True).start()
        self.installs += 1
        ok, log = self._answer()
        if not ok:
            self.stop()
            raise RuntimeError(f"the Blender worker did not start:\n{log[-4000:]}")

    @staticmethod
    def _read(proc, lines) -> None:
        for line in proc.stdout:
            lines.put(line)
        lines.put(None)

    def _answer(self) -> tuple[bool, str]:
        """(ok, output) of the running request: its lines up to the answer line."""
        log = []
        while True:
            try:
                line = self.lines.get(timeout=self.timeout)
            except queue.Empty:
                self.stop()
                return False, "".join(log) + f"\n(no answer within {self.timeout:g} s: the worker was stopped)"
            if line is None:
                code = self.proc.wait()
                self.proc = None
                return False, "".join(log) + f"\n(the worker ended with exit status {code})"
            if line.startswith(MARK):
                answer = json.loads(line[len(MARK):])
                return answer["ok"], "".join(log) + answer.get("error", "")
            log.append(line)

    def run(self, module_file: str, case: str, cwd: Path) -> tuple[bool, str]:
        """Run ``case_<case>`` of the test module ``module_file`` in the worker: (ok, output)."""
        if self.proc is None or self.proc.poll() is not None:
            self._start()
        request = {"module": Path(module_file).stem, "case": case, "cwd": str(cwd)}
        self.proc.stdin.write(json.dumps(request) + "\n")
        self.proc.stdin.flush()
        return self._answer()

    def stop(self) -> None:
        if self.proc is not None:
            self.proc.kill()
            self.proc.wait()
            self.proc = None


def run_fresh(zip_path: Path, module_file: str, case: str, cwd: Path, timeout: float = 600.0) -> tuple[bool, str]:
    """Run one case in a fresh Blender process of its own (install, case, exit): (ok, output)."""
    env = dict(os.environ, BLENDER_USER_RESOURCES=tempfile.mkdtemp(prefix="ple-blender-"))
    res = subprocess.run([sys.executable, str(HERE / "blender_worker.py"), str(zip_path), "--once",
                          Path(module_file).stem, case], cwd=cwd, capture_output=True, text=True, timeout=timeout,
                         env=env)
    answers = [json.loads(line[len(MARK):]) for line in res.stdout.splitlines() if line.startswith(MARK)]
    ok = len(answers) == 2 and answers[-1]["ok"]  # installed, then the case
    return ok, res.stdout[-4000:] + res.stderr[-4000:] + "".join(a.get("error", "") for a in answers)


# ----- worker (Blender side) ----------------------------------------------------------------------------
def install(zip_path: str):
    """Install and enable the zip in this headless bpy; (bpy, the environment's core, or None in
    a Blender whose Python has only its own packages: ``PLE_WORKER_TRUTH=none``)."""
    import importlib

    import bpy

    ple = None
    if os.environ.get("PLE_WORKER_TRUTH") != "none":
        import ple

        for name in CORE_MODULES:
            importlib.import_module(f"ple.{name}")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default", enable_on_install=True)
    return bpy, ple


def reset(bpy) -> None:
    """A clean state for the next case: an empty scene (the add-on stays enabled), the add-on's
    preferences at their defaults, scripts not trusted, the add-on's session forgotten."""
    bpy.ops.wm.read_homefile(use_empty=True)  # load_post: the add-on forgets the drawn state
    addon = bpy.context.preferences.addons.get(ADDON)
    if addon is not None:
        prefs = addon.preferences
        for name, value in sys.modules[f"{ADDON}.prefs"].DEFAULTS.items():
            setattr(prefs, name, value)
    bpy.context.preferences.filepaths.use_scripts_auto_execute = False
    session = sys.modules.get(f"{ADDON}.session")
    if session is not None:
        session.SESSION.reset()
    else:
        rig = sys.modules[f"{ADDON}.rig"]
        rig._trusted.clear()
        rig._pending_reports.clear()


def run_case(bpy, core, module: str, case: str) -> dict:
    """Run ``case_<case>`` of test module ``module`` with ``bpy``, ``ple_ext`` and ``core`` bound in
    the test modules that hold them."""
    import importlib

    try:
        mod = importlib.import_module(module)
        ext = sys.modules[ADDON]
        for m in list(sys.modules.values()):
            if getattr(m, "__name__", "").startswith(("test_", "bpy_only_")) and hasattr(m, "ple_ext"):
                m.bpy, m.ple_ext, m.core = bpy, ext, core
        getattr(mod, f"case_{case}")()
        return {"ok": True}
    except BaseException:  # noqa: BLE001 - the case's failure goes back to pytest
        return {"ok": False, "error": traceback.format_exc()}


def answer(result: dict) -> None:
    sys.stdout.flush()
    sys.stderr.flush()
    print(MARK + json.dumps(result), flush=True)


def main(argv: list[str]) -> int:
    sys.path.insert(0, str(HERE))
    try:
        bpy, core = install(argv[0])
    except BaseException:  # noqa: BLE001
        answer({"ok": False, "error": traceback.format_exc()})
        return 1
    answer({"ok": True})
    if len(argv) == 4 and argv[1] == "--once":
        answer(run_case(bpy, core, argv[2], argv[3]))
        return 0
    for line in sys.stdin:
        request = json.loads(line)
        os.chdir(request["cwd"])
        try:
            reset(bpy)
        except BaseException:  # noqa: BLE001
            answer({"ok": False, "error": "resetting Blender failed:\n" + traceback.format_exc()})
            continue
        answer(run_case(bpy, core, request["module"], request["case"]))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

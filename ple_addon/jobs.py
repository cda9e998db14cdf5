"""Contained work for the add-on: lattice programs and long core calls (filtered evaluation,
tessellation) run in a child process (``ple.program.runner``) under the limits of the add-on
preferences, so that an endless loop, a memory bomb or a long LiL costs the child, never Blender.

Blocking calls (running a program, a filtered redraw, applying edits) wait at most the program
time limit. Jobs (tessellate, export, LiL) are followed step by step by a modal operator
(``ops.base.SteppedOperator``): progress in the status bar and the panel, Esc stops the child
at once, and nothing is applied to the rig before the child's result is complete.
"""

from __future__ import annotations

from . import prefs
from .corelink import runner

HINTS = runner.Hints(timeout="raise the time limit in the add-on preferences (Edit › Preferences › Add-ons › PLE)",
                     memory="raise the memory limit in the add-on preferences (Edit › Preferences › Add-ons › PLE)")
TICK = 0.05  # seconds a step waits for the child before the modal operator looks at events again


def seconds(name: str) -> float | None:
    """A time limit of the preferences in seconds, None for none (0)."""
    value = float(prefs.get(name))
    return value if value > 0 else None


def run_text(text: str, name: str, params: dict):
    """(lattice, inputs) of program ``text`` run contained (``runner.run_text``)."""
    return runner.run_text(text, name, params, seconds("program_seconds"), prefs.max_bytes(), HINTS)


def call(work, name: str, what: str):
    """``work()`` run contained, waiting at most the program time limit: its result."""
    return runner.Job(work, name, seconds("program_seconds"), prefs.max_bytes(), what, HINTS).result()


def start(work, name: str, what: str, beyond: bool = False):
    """A job: ``work()`` started contained under the job time limit (and the memory limit, unless
    the user chose to go ``beyond`` the limits)."""
    return runner.Job(work, name, seconds("job_seconds"), None if beyond else prefs.max_bytes(), what, HINTS)


def follow(job, progress):
    """Steps following ``job``: yields ``progress(items so far)`` (a fraction) every tick and
    returns (items, result). Closing the generator (Esc) or any error stops the child."""
    items: list = []
    try:
        while not job.poll(TICK):
            items += job.take()
            yield progress(items)
        items += job.take()
        return items, job.result()
    finally:
        job.cancel()


def register() -> None:
    pass


def unregister() -> None:
    pass

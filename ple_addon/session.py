"""What the add-on remembers during one Blender session, in one object: the drawn state of every
rig, the trust the user gave, the busy flag that keeps the add-on's own writes from re-entering
its update callbacks, the reports of live editing waiting for the Info editor, and the caches of
the features. Nothing here is saved in the .blend; loading a file, undo and redo forget the
drawn state (``forget_drawn``), a test's fresh start forgets everything (``reset``).
"""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass, field

import bpy

REPORTS_KEPT = 50  # background sessions never flush their reports: keep only the latest


@dataclass
class RigState:
    """What the add-on last drew for a rig, to tell user moves from its own writes."""

    program_key: tuple = ()
    inputs: list | None = None  # the program's inputs (runtime.Param), as its child process gave them
    base: object = None
    lattice: object = None
    expected: dict = field(default_factory=dict)
    signature: tuple = ()
    topology: tuple = ()  # (key, (node_index, beam ends)) of the last unfiltered region drawn
    rigid: bool = False  # the region was drawn before G, its object placed by G (a move of G moves it)
    hull: tuple | None = None  # (node_index and limit it was chosen for, balls, beam ends): ``live_view``
    hull_drawn: bool = False  # a live move drew the hull only: ``settle`` draws the region in full
    cumulative: tuple = (False, False, False)  # the Cumulative toggles when last drawn
    region: tuple = ()  # (region_min, region_max) last drawn without error
    refused: bool = False  # the status is a refused setting: it stays until the user's next edit
    clamped: str = ""  # inputs set beyond their Range and clamped, for the status of the next drawing


@dataclass
class Session:
    states: dict = field(default_factory=dict)  # rig uid -> RigState
    owner: dict = field(default_factory=dict)  # rig uid -> session_uid of the object holding it (a copy has another)
    trusted: set = field(default_factory=set)  # uids of the open file's rigs whose program the user trusts
    kept_trust: dict = field(default_factory=dict)  # .blend path -> {rig uid: program fingerprint} (keep_trust)
    on_disk: dict = field(default_factory=dict)  # rig uid -> fingerprint of its program as the open file holds it
    busy: bool = False  # the add-on itself writes to a rig: its update callbacks stay quiet
    reports: list = field(default_factory=list)  # messages of live editing for the Info editor
    object_count: int | None = None  # objects in the scene at the last update (None: not yet counted)
    caches: dict = field(default_factory=dict)  # a feature's cache by name (bodies, CLGs, Möbius lattices)

    @contextmanager
    def quiet(self):
        """Within: the add-on's own writes (settings set back, several settings at once) do not
        trigger its update callbacks."""
        was, self.busy = self.busy, True
        try:
            yield
        finally:
            self.busy = was

    def state(self, uid: str) -> RigState:
        return self.states.setdefault(uid, RigState())

    def cache(self, name: str) -> dict:
        return self.caches.setdefault(name, {})

    def forget_drawn(self) -> None:
        """After undo, redo or loading a file: positions are then not user moves."""
        self.states.clear()
        self.owner.clear()
        self.object_count = None

    def keep_trust(self, path: str, programs: dict) -> None:
        """The trusts of the file ``path`` (saved, or left for another file or File › New), for the
        programs it holds on disk (``programs``: rig uid -> fingerprint)."""
        if path:
            self.kept_trust[path] = {u: fp for u, fp in programs.items() if u in self.trusted}

    def restore_trust(self, path: str, programs: dict) -> None:
        """The file ``path`` was opened, holding ``programs``: a rig is trusted if the user trusted
        it in this file, for the very program it holds; another file, or another program under the
        same path and rig id, trusts nothing."""
        kept = self.kept_trust.get(path, {}) if path else {}
        self.trusted.clear()
        self.trusted.update(u for u, fp in programs.items() if u in kept and kept[u] == fp)
        self.on_disk = dict(programs)

    def reset(self) -> None:
        """Everything forgotten, as in a new Blender session."""
        self.forget_drawn()
        self.trusted.clear()
        self.kept_trust.clear()
        self.on_disk.clear()
        self.busy = False
        self.reports.clear()
        self.caches.clear()


SESSION = Session()


def notify(rig, message: str) -> None:
    """A problem met outside an operator (live editing): besides the panel's status line it goes
    to the Info editor, through the ``ple.report`` operator run from a timer right after the
    handler (handlers cannot report; in background mode timers never fire: ``flush_reports``)."""
    SESSION.reports.append(f"{rig.name}: {message}")
    del SESSION.reports[:-REPORTS_KEPT]
    if not bpy.app.background and not bpy.app.timers.is_registered(flush_reports):
        bpy.app.timers.register(flush_reports, first_interval=0.0)


def flush_reports():
    while SESSION.reports:
        msg = SESSION.reports.pop(0)
        try:
            bpy.ops.ple.report(message=msg)
        except RuntimeError:
            print(f"PLE: {msg}")
    return None


def register() -> None:
    pass


def unregister() -> None:
    if bpy.app.timers.is_registered(flush_reports):
        bpy.app.timers.unregister(flush_reports)
    SESSION.forget_drawn()

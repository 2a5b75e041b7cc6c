"""Long work as cancellable jobs: one operator base class for every MirrorCap operator.

Every operator derives from :class:`MirrorCapOperator` (after MPFB2): its work raises, and
the base class turns a :class:`core.common.errors.MirrorCapError` into a ``self.report`` error (any
other exception into an "internal error" report, its traceback on the console) and returns
``{'CANCELLED'}`` -- unless ``MIRRORCAP_RAISE=1`` (the tests), when it propagates.

A job operator splits its work in three, so long work never blocks Blender's UI and a
cancelled run leaves nothing behind:

``prepare(context)``  on the main thread: read properties and Blender data, return the work;
``work(progress)``    pure core (no ``bpy``): may run on a worker thread; writes files only
                      atomically at its very end; calls ``progress(fraction)`` often;
``finish(context, result)``  on the main thread: the only place the scene changes.

Invoked from the UI, the job runs modally: the work on a thread, a progress bar in the
window manager and a status line, Esc (or right-click) cancels -- the next
``progress`` call raises :class:`Cancelled` in the work, ``finish`` never runs, and the scene
is as it was. From a script (``bpy.ops.mirrorcap.*()``, or whenever there is no window) the
same three steps run in order on the calling thread. The work runs with one BLAS thread and one
OpenCV thread (:func:`core.common.threads.limited_threads`). ``cancel_after_steps`` (hidden) cancels
after that many progress calls exactly as Esc would: scripts and tests use it.
"""

from __future__ import annotations

import os
import threading
import time
import traceback

import bpy
from bpy.props import IntProperty

from ...core.common.errors import MirrorCapError
from ...core.common.log import MessageLog
from ...core.common.threads import limited_threads


class Cancelled(Exception):
    """The user (or ``cancel_after_steps``) cancelled the job."""


class Progress:
    """``progress(fraction, text='')`` for the work; raises :class:`Cancelled` once cancelled."""

    def __init__(self, cancel_after_steps: int = 0):
        self.fraction = 0.0
        self.text = ""
        self.steps = 0
        self.cancel_after_steps = cancel_after_steps
        self.cancel_event = threading.Event()

    def __call__(self, fraction: float, text: str = "") -> None:
        self.fraction = min(max(float(fraction), 0.0), 1.0)
        if text:
            self.text = text
        self.steps += 1
        if self.cancel_after_steps and self.steps >= self.cancel_after_steps:
            self.cancel_event.set()
        if self.cancel_event.is_set():
            raise Cancelled()

    def stage(self, start: float, end: float, text: str = ""):
        """A callback ``(done, total)`` mapping a stage's count onto ``[start, end]``."""

        def cb(done, total=None, *_, **__):
            frac = done / total if total else 0.0
            self(start + (end - start) * min(frac, 1.0), text)

        return cb


def _raising() -> bool:
    return os.environ.get("MIRRORCAP_RAISE") == "1"


class MirrorCapOperator(bpy.types.Operator):
    """Base of every MirrorCap operator: ``run(context)`` does the work and returns a message.
    The core's messages of the run (``self.messages``, a :class:`...core.common.log.MessageLog`
    handed to the core as ``log=``) are replayed with ``self.report`` once the run succeeded."""

    bl_options = {"REGISTER", "UNDO"}

    @property
    def messages(self) -> MessageLog:
        log = getattr(self, "_messages", None)
        if log is None:
            log = self._messages = MessageLog()
        return log

    def _replay_messages(self) -> None:
        self.messages.replay(self.report)
        self._messages = None

    def run(self, context):  # pragma: no cover - overridden
        raise NotImplementedError

    def guarded(self, fn, *args):
        """``(ok, value)`` of ``fn(*args)``; errors become reports (see the module text)."""
        try:
            return True, fn(*args)
        except Cancelled:
            self.report({"WARNING"}, f"{self.bl_label}: cancelled; nothing was changed")
            return False, None
        except MirrorCapError as exc:
            if _raising():
                raise
            self.report({"ERROR"}, str(exc))
            return False, None
        except Exception as exc:  # a bug: say so in the UI, keep the traceback for the console
            if _raising():
                raise
            traceback.print_exc()
            self.report({"ERROR"}, f"{self.bl_label}: internal error ({type(exc).__name__}: {exc}); "
                                   "details in the system console")
            return False, None

    def execute(self, context):
        ok, message = self.guarded(self.run, context)
        if not ok:
            return {"CANCELLED"}
        if message:
            self.report({"INFO"}, message)
        self._replay_messages()
        return {"FINISHED"}


class MirrorCapJobOperator(MirrorCapOperator):
    """Base of the long operators: ``prepare`` / ``work`` / ``finish`` (see the module text)."""

    cancel_after_steps: IntProperty(
        name="Cancel After Steps", default=0, min=0, options={"HIDDEN", "SKIP_SAVE"},
        description="Cancel after this many progress steps, exactly as pressing Esc would (scripts, tests)")

    def prepare(self, context):  # pragma: no cover - overridden
        raise NotImplementedError

    def finish(self, context, result):  # pragma: no cover - overridden
        raise NotImplementedError

    def run(self, context):
        work = self.prepare(context)
        progress = Progress(self.cancel_after_steps)
        with limited_threads():             # one BLAS and one OpenCV thread (core/common/threads.py)
            result = work(progress)
        return self.finish(context, result)

    # -- modal -------------------------------------------------------------
    def invoke(self, context, event):
        if context.window is None or bpy.app.background:
            return self.execute(context)
        ok, work = self.guarded(self.prepare, context)
        if not ok:
            return {"CANCELLED"}
        self._progress = Progress(self.cancel_after_steps)
        self._outcome = {}

        def target():
            try:
                with limited_threads():
                    self._outcome["result"] = work(self._progress)
            except BaseException as exc:  # handed to the main thread
                self._outcome["error"] = exc

        self._thread = threading.Thread(target=target, name=f"mirrorcap:{self.bl_idname}", daemon=True)
        self._started = time.perf_counter()
        wm = context.window_manager
        self._timer = wm.event_timer_add(0.1, window=context.window)
        wm.progress_begin(0, 1000)
        wm.modal_handler_add(self)
        self._thread.start()
        return {"RUNNING_MODAL"}

    def _status(self, context, text):
        if context.workspace is not None:
            context.workspace.status_text_set(text)

    def _end(self, context):
        wm = context.window_manager
        wm.event_timer_remove(self._timer)
        wm.progress_end()
        self._status(context, None)

    def modal(self, context, event):
        if event.type in {"ESC", "RIGHTMOUSE"} and event.value == "PRESS":
            self._progress.cancel_event.set()
        if event.type != "TIMER":
            return {"RUNNING_MODAL"}
        if self._thread.is_alive():
            p = self._progress
            context.window_manager.progress_update(int(p.fraction * 1000))
            cancel = " -- cancelling" if p.cancel_event.is_set() else " (Esc to cancel)"
            self._status(context, f"MirrorCap {self.bl_label}: {p.fraction * 100:.0f} % {p.text}{cancel}")
            return {"RUNNING_MODAL"}
        self._end(context)
        if "error" in self._outcome:
            exc = self._outcome["error"]

            def rethrow():
                raise exc

            self.guarded(rethrow)
            return {"CANCELLED"}
        ok, message = self.guarded(self.finish, context, self._outcome["result"])
        if not ok:
            return {"CANCELLED"}
        elapsed = time.perf_counter() - self._started
        self.report({"INFO"}, f"{message} ({elapsed:.1f} s)" if message else f"done in {elapsed:.1f} s")
        self._replay_messages()
        return {"FINISHED"}

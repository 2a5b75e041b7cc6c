"""Ctrl-C on the command line: the command stops with "interrupted" (exit 130) whenever it
comes, never with a traceback from the code that happened to be running.

Python raises ``KeyboardInterrupt`` wherever the main thread is. Three places could not take it
(stop 49: ``mirrorcap batch`` interrupted 0.3-0.8 s after its start on a loaded machine, ``bake``
and ``track`` at moments from 0.1 to 6 s):

- the command's setup: inside ``import cv2`` it became an ``ImportError`` traceback (exit 1),
  and inside the ctypes callback by which threadpoolctl finds the BLAS libraries it was
  swallowed, so the command ran to its end and exited 0 (3 of 40 interrupts);
- a batch worker's start: between the spawn of the process and the write of what it is to run,
  it left the new worker reading an empty pipe ("EOFError: Ran out of input", 1 of 60). Blocking
  SIGINT in the main thread does not prevent it: the task queue's feeder thread takes the
  signal, and Python still raises the exception in the main thread;
- Blender's start (``import bpy``, by ``bake``, ``retarget``, ``fap`` and ``demo``): raised inside
  Blender's start-up scripts, it left Blender half-registered and the process died of a
  segmentation fault (3 of 14 interrupts of ``mirrorcap bake`` 0.1-6 s after its start).

And an import that a Ctrl-C interrupts -- each command imports what it needs as it starts --
turns the ``KeyboardInterrupt`` into an ``ImportError`` ("initialization failed" from SciPy's
distance module, 1 of 14 interrupts of ``mirrorcap track``): :func:`caused_by_ctrl_c` tells such
an error from a real one.

:func:`interrupts_held` runs such a block with Ctrl-C recorded, not raised, and raises it once
the block is done."""

from __future__ import annotations

import signal
import threading
from contextlib import contextmanager


@contextmanager
def interrupts_held():
    """Within the block a Ctrl-C (SIGINT) is only recorded; when the block ends without an
    error, a recorded one goes to the handler that was in place (``KeyboardInterrupt`` by
    default). Where SIGINT is ignored (a shell's background job, ``nohup``) or has no Python
    handler, or this is not the main thread, nothing changes."""
    previous = signal.getsignal(signal.SIGINT)
    if threading.current_thread() is not threading.main_thread() or not callable(previous):
        yield
        return
    seen = []
    signal.signal(signal.SIGINT, lambda signum, frame: seen.append(frame))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if seen:
        previous(signal.SIGINT, seen[0])


def caused_by_ctrl_c(exc: BaseException) -> bool:
    """Whether ``exc`` was raised while a Ctrl-C (``KeyboardInterrupt``) was being raised or
    handled: an import it interrupted turns it into an ``ImportError``."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False

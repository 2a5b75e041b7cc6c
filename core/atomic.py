"""Atomic output: nothing half-written on failure.

Every output file is first written to a temporary file in the destination folder
and renamed over the target only once all files of a result are complete.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

from .errors import InputError


def default_file_mode() -> int:
    """The mode a plain ``open(path, "w")`` would give a new file (0666 minus umask)."""
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def write_files_atomically(contents: dict) -> None:
    """Write ``{path: str | bytes}`` so that either every file is replaced by its new
    content or (on any error) none is touched and no temporary file is left."""
    temps = []
    mode_bits = default_file_mode()
    try:
        for path, data in contents.items():
            path = Path(path)
            folder = path.parent if str(path.parent) else Path(".")
            if not folder.is_dir():
                raise InputError(f"output folder {folder} does not exist")
            fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=folder)
            temps.append((tmp, path))
            os.chmod(tmp, mode_bits)  # mkstemp creates 0600; give the file the usual umask-based mode
            mode = "wb" if isinstance(data, bytes) else "w"
            kwargs = {} if isinstance(data, bytes) else {"encoding": "utf-8", "newline": ""}
            with os.fdopen(fd, mode, **kwargs) as fh:
                fh.write(data)
                fh.flush()
                os.fsync(fh.fileno())
        for tmp, path in temps:
            os.replace(tmp, path)
        temps = []
    finally:
        for tmp, _ in temps:
            with contextlib.suppress(OSError):
                os.unlink(tmp)

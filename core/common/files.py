"""File helpers: atomic output (nothing half-written on failure) and reading the
project's JSON files with one clear error.

Every output file is first written to a temporary file in the destination folder
and renamed over the target only once all files of a result are complete.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from pathlib import Path

from .errors import InputError


def default_file_mode() -> int:
    """The mode a plain ``open(path, "w")`` would give a new file (0666 minus umask)."""
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def check_output_paths(*paths) -> None:
    """Refuse, with one clear message, outputs that could not be written -- before any work is done, so that a long
    take does not fail at its end: a folder that does not exist or cannot be written to, a path that is a folder,
    one file named for two outputs. ``None`` entries (outputs not asked for) are skipped."""
    named = {}
    for path in paths:
        if path is None:
            continue
        path = Path(path)
        folder = path.parent                      # Path("take.c3d").parent is Path(".")
        if not folder.is_dir():
            raise InputError(f"output folder {folder} does not exist")
        if path.is_dir():
            raise InputError(f"output {path} is a folder: name the file to write")
        if not os.access(folder, os.W_OK | os.X_OK):
            raise InputError(f"cannot write to output folder {folder}")
        key = path.resolve()
        if key in named:
            raise InputError(f"{path} is named for two outputs: each needs a file of its own")
        named[key] = path


def output_folder(path) -> Path:
    """The folder ``path`` for a command's outputs, made (with its parents) where it does not exist yet; one clear
    message when it cannot be: a file of that name, no permission."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise InputError(f"output folder {path} is a file: name a folder for the outputs")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot make output folder {path}: {exc.strerror or exc}") from None
    return path


def write_files_atomically(contents: dict) -> None:
    """Write ``{path: str | bytes}`` so that either every file is replaced by its new
    content or (on any error) none is touched and no temporary file is left."""
    check_output_paths(*contents)
    temps = []
    mode_bits = default_file_mode()
    try:
        for path, data in contents.items():
            path = Path(path)
            fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
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


def read_text(path, kind: str) -> str:
    """The text of ``path`` (UTF-8, a byte-order mark allowed); ``kind`` names the file
    in errors ("camera file", "pairs file", ...)."""
    path = Path(path)
    try:
        return path.read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise InputError(f"cannot read {kind} {path}: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise InputError(f"{kind} {path} is not UTF-8 text") from None


def read_json(path, kind: str):
    """Parse the JSON file ``path``; ``kind`` names it in errors."""
    text = read_text(path, kind)
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"{kind} {path} is not valid JSON ({exc.msg} at line {exc.lineno})") from None

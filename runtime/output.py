"""Output folders that are checked before any work and never left half-written, and JSON that numpy/jax
values survive."""

from __future__ import annotations

import contextlib
import json
import math
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np


def to_jsonable(obj):
    """Convert numpy/jax scalars and arrays (recursively) to plain JSON values; NaN becomes null."""
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if hasattr(obj, "__array__") and not isinstance(obj, (str, bytes)):
        arr = np.asarray(obj)
        if arr.ndim == 0:
            return to_jsonable(arr.item())
        return [to_jsonable(v) for v in arr.tolist()]
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, (np.bool_,)):
        return bool(obj)
    return obj


def dumps(obj, indent: int | None = 2) -> str:
    return json.dumps(to_jsonable(obj), indent=indent, allow_nan=False)


def check_output(out: str | Path, flag: str = "--out") -> Path:
    """Check, before any work, that ``out`` can become the output folder: it is a folder or a new
    path, and the folder that will hold it (and its staging folder) can be written. Returns it
    as an absolute path; a problem is one-line :class:`~runtime.errors.UsageError` naming ``flag``.
    """
    from runtime.errors import UsageError

    out = Path(os.path.abspath(out))
    if out.exists() and not out.is_dir():
        raise UsageError(f"{flag}: {out} is a file, expected a folder (or a new path)")
    parent = next(p for p in out.parents if p.exists())
    if not parent.is_dir():
        raise UsageError(f"{flag}: {parent} is a file, expected a folder (or a new path)")
    for folder in (parent, out) if out.is_dir() else (parent,):
        try:
            tempfile.TemporaryDirectory(dir=folder, prefix=f".{out.name}.probe-").cleanup()
        except OSError as exc:
            raise UsageError(f"{flag}: cannot write in {folder}: {exc.strerror or exc}") from None
    return out


@contextlib.contextmanager
def staged_output(out: str | Path) -> Iterator[Path]:
    """Yield a staging folder beside ``out``; on success move its files into ``out``.

    ``out`` is checked first (:func:`check_output`; the command line checks it before any
    work). If the body raises or is interrupted, the staging folder is removed and ``out`` is
    untouched, so a failed run never leaves a half-written report behind; Ctrl-C and SIGTERM
    wait while the files are moved into place.
    """
    from runtime.errors import Interrupted, interrupts_held

    shown = str(out)
    out = check_output(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    stage = out.parent / f".{out.name}.partial-{os.getpid()}"
    shutil.rmtree(stage, ignore_errors=True)
    stage.mkdir()
    try:
        try:
            yield stage
        except Interrupted as exc:
            exc.unwritten = exc.unwritten or shown
            raise
        try:
            with interrupts_held():
                out.mkdir(parents=True, exist_ok=True)
                for item in sorted(stage.rglob("*")):
                    target = out / item.relative_to(stage)
                    if item.is_dir():
                        target.mkdir(parents=True, exist_ok=True)
                    else:
                        os.replace(item, target)
        except Interrupted as exc:
            exc.written = True
            raise
    finally:
        shutil.rmtree(stage, ignore_errors=True)




def check_output_file(path: str | Path, flag: str) -> Path:
    """Check, before any work, that ``path`` can be written as a file kept up to date (replaced
    atomically through a temporary file beside it): not a folder, in a folder that exists and can
    be written. Returns it; a problem is one-line :class:`~runtime.errors.UsageError` naming ``flag``."""
    from runtime.errors import UsageError

    path = Path(path)
    if path.is_dir():
        raise UsageError(f"{flag}: {path} is a folder, expected a file")
    if not path.parent.is_dir():
        raise UsageError(f"{flag}: no such folder: {path.parent}")
    try:
        tempfile.TemporaryDirectory(dir=path.parent, prefix=f".{path.name}.probe-").cleanup()
    except OSError as exc:
        raise UsageError(f"{flag}: cannot write in {path.parent}: {exc.strerror or exc}") from None
    return path

"""Atomic output files: write to a temporary file in the destination folder, then rename, so a
failed or interrupted write never leaves a half-written result (and never clobbers a good one)."""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path
from typing import Iterator

from cmbs.errors import CmbsError


def checked_output(path: str | os.PathLike, suffixes: tuple[str, ...], what: str) -> Path:
    """``path`` as a Path after checking its extension and that its folder exists."""
    path = Path(path)
    if path.suffix.lower() not in suffixes:
        raise CmbsError(f"{path}: {what} must end in {' or '.join(suffixes)}, got {path.suffix or 'no extension'!r}")
    directory = path.parent if str(path.parent) else Path(".")
    if not directory.is_dir():
        raise CmbsError(f"{path}: directory {str(directory)!r} does not exist")
    return path


@contextlib.contextmanager
def atomic_path(path: Path) -> Iterator[str]:
    """Yield a temporary file name next to ``path``; on success it replaces ``path`` (with the
    permissions a newly created file gets under the current umask)."""
    handle, temporary = tempfile.mkstemp(dir=path.parent if str(path.parent) else ".", prefix=f".{path.name}.",
                                         suffix=path.suffix)
    os.close(handle)
    try:
        yield temporary
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(temporary, 0o666 & ~umask)
        os.replace(temporary, path)
    finally:
        if os.path.exists(temporary):
            os.unlink(temporary)

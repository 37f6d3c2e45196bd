"""Atomic output files: write to a temporary file in the destination folder, then rename, so a
failed or interrupted write never leaves a half-written result (and never clobbers a good one).

Every output path is checked before any work (:func:`checked_output`): its extension, that it
is not a folder, that its name fits the file system, and that a file can be created in its
folder (a probe temporary, created and removed).  Temporaries are named
``.<target name>.cmbs-partial-<pid>-<random><suffix>``: one removed on any exception (also
KeyboardInterrupt, and SIGTERM in the CLI); one left by a writer killed outright (SIGKILL, power
loss) is removed by the next write to the same target once its process has gone.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import tempfile
from pathlib import Path
from typing import Iterator

from cmbs.errors import CmbsError

#: the mark of a cmbs temporary file in its name
PARTIAL = ".cmbs-partial-"
#: target names longer than this are shortened (with a digest) in their temporaries' names
SHORT_NAME = 100


def checked_output(path: str | os.PathLike, suffixes: tuple[str, ...], what: str) -> Path:
    """``path`` as a Path after checking that a file of that name can be written there: its
    extension is one of ``suffixes``, its folder exists, it is not a folder, its name is not
    too long, and a file can be created in the folder (CmbsError naming ``what`` otherwise)."""
    path = Path(path)
    if path.suffix.lower() not in suffixes:
        raise CmbsError(f"{path}: {what} must end in {' or '.join(suffixes)}, got {path.suffix or 'no extension'!r}")
    directory = _folder(path)
    longest = _name_max(directory)
    if len(os.fsencode(path.name)) > longest:
        raise CmbsError(f"{path}: {what}: the file name is {len(os.fsencode(path.name))} bytes long, more than the "
                        f"{longest} the file system allows")
    try:
        if not directory.is_dir():
            raise CmbsError(f"{path}: directory {str(directory)!r} does not exist")
        if path.is_dir():
            raise CmbsError(f"{path}: {what} names a folder; give a file name")
        handle, probe = tempfile.mkstemp(dir=directory, prefix=temporary_prefix(path), suffix=path.suffix)
    except OSError as error:
        raise CmbsError(f"{path}: {what} cannot be written in {str(directory)!r} ({error.strerror})") from None
    os.close(handle)
    os.unlink(probe)
    return path


def _folder(path: Path) -> Path:
    return path.parent if str(path.parent) else Path(".")


def _name_max(directory: Path) -> int:
    """The longest file name (bytes) the file system of ``directory`` allows (255 if unknown)."""
    try:
        return os.pathconf(directory, "PC_NAME_MAX")
    except (OSError, ValueError, AttributeError):
        return 255


def temporary_prefix(path: Path, pid: int | None = None) -> str:
    """The start of the name of a temporary that process ``pid`` (default: this one) writes for
    ``path``: ``.<name>.cmbs-partial-<pid>-``."""
    return f"{_temporary_stem(path)}{os.getpid() if pid is None else pid}-"


def _temporary_stem(path: Path) -> str:
    """``.<name>.cmbs-partial-``, a long name shortened (with a digest of it) so that the
    temporary's name stays within the file system's limit."""
    name = path.name
    if len(name) > SHORT_NAME:
        name = f"{name[:SHORT_NAME - 12]}~{hashlib.sha1(os.fsencode(name)).hexdigest()[:10]}"
    return f".{name}{PARTIAL}"


def remove_stale_temporaries(path: Path) -> None:
    """Remove the temporaries of ``path`` whose writing process no longer runs (killed outright
    while writing); those of running processes are left alone."""
    directory = _folder(path)
    start = _temporary_stem(path)
    try:
        names = [name for name in os.listdir(directory) if name.startswith(start)]
    except OSError:
        return
    for name in names:
        pid_text = name[len(start):].split("-", 1)[0]
        if pid_text.isdigit() and not _running(int(pid_text)):
            with contextlib.suppress(OSError):
                os.unlink(directory / name)


def _running(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True          # someone else's process, or no way to tell: keep its file
    return True


@contextlib.contextmanager
def atomic_path(path: Path) -> Iterator[str]:
    """Yield a temporary file name next to ``path``; on success it replaces ``path`` (with the
    permissions a newly created file gets under the current umask).  The temporary is removed
    on any exception; stale temporaries of ``path`` left by killed writers are removed first."""
    remove_stale_temporaries(path)
    handle, temporary = tempfile.mkstemp(dir=_folder(path), prefix=temporary_prefix(path), suffix=path.suffix)
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

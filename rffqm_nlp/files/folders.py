"""Output folders: checked before a long computation, and replaced whole.

A command that writes a folder of files writes them into a staging folder next to it and
replaces the output folder whole (:func:`replace_folder`): a kill at any moment leaves
either the complete old folder or the complete new one, and the next run into the same
place cleans up what the killed one left (:func:`recover_folder`).
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import os
import re
import secrets
import shutil
import sys
from collections.abc import Iterator
from pathlib import Path

from ..errors import InputError
from .writing import DIR_MODE, FILE_MODE


def check_out_dir(out: Path, force: bool) -> None:
    """Refuse an output folder that is a file, or not empty without ``force``, or cannot be
    created, before a long computation. Touches nothing but what a killed run left next to
    ``out`` (see :func:`recover_folder`)."""
    recover_folder(out)
    if out.exists():
        if not out.is_dir():
            raise InputError(f"{out} exists and is not a folder; choose another --out")
        if any(out.iterdir()) and not force:
            raise InputError(f"{out} exists and is not empty; pass --force to replace it "
                             "(the whole folder is replaced)")
    existing = out.absolute()
    while not existing.exists():
        existing = existing.parent
    if not existing.is_dir():
        raise InputError(f"cannot create {out}: {existing} is not a folder")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise InputError(f"cannot write into {existing} (permission denied)")


#: The kinds of sibling folder a replacement of ``out`` makes: ".<out>.<kind>-<pid>-<token>".
#: "staging" is being written (or, after an exchange, holds the old folder being removed),
#: "ready" is complete and waits to be renamed in, "aside" is the old folder moved away.
_KINDS = ("staging", "ready", "aside")


def _sibling(out: Path, kind: str, token: str) -> Path:
    return out.with_name(f".{out.name}.{kind}-{os.getpid()}-{token}")


def _leftovers(out: Path) -> list[tuple[str, Path]]:
    """(kind, path) of every folder next to ``out`` that a dead process made while
    replacing ``out``."""
    pattern = re.compile(rf"\.{re.escape(out.name)}\.({'|'.join(_KINDS)})-(\d+)-\w+")
    found = []
    with contextlib.suppress(FileNotFoundError, NotADirectoryError):
        for entry in out.parent.iterdir():
            match = pattern.fullmatch(entry.name)
            if match and not _alive(int(match[2])):
                found.append((match[1], entry))
    return found


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def recover_folder(out: str | os.PathLike) -> None:
    """Finish or undo a replacement of ``out`` that a killed process left half-done, then
    remove the staging folders of dead processes next to ``out``.

    Only a replacement by two renames can leave ``out`` missing (between moving the old
    folder aside and renaming the new one in): the complete new folder ("ready") is renamed
    in, else the old one ("aside") is moved back.
    """
    out = Path(os.path.realpath(out))
    found = _leftovers(out)
    if not os.path.lexists(out):
        for kind in ("ready", "aside"):
            candidates = sorted((p for k, p in found if k == kind),
                                key=lambda p: p.stat().st_ctime)
            if candidates:
                with contextlib.suppress(FileNotFoundError):
                    os.rename(candidates[-1], out)
                break
    for _, path in found:
        shutil.rmtree(path, ignore_errors=True)


def _renameat2():
    """libc's renameat2 (Linux, glibc 2.28 or later), or None."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        func = ctypes.CDLL(None, use_errno=True).renameat2
    except (OSError, AttributeError):
        return None
    func.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p,
                     ctypes.c_uint]
    func.restype = ctypes.c_int
    return func


#: libc's renameat2, or None where there is none (then :func:`exchange` swaps nothing).
RENAMEAT2 = _renameat2()
_AT_FDCWD = -100
_RENAME_EXCHANGE = 2


def exchange(a: Path, b: Path) -> bool:
    """Swap the folders ``a`` and ``b`` in one atomic step; False where the system or file
    system cannot (then nothing changed)."""
    if RENAMEAT2 is None:
        return False
    if RENAMEAT2(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    code = ctypes.get_errno()
    if code in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP):
        return False
    raise OSError(code, os.strerror(code), str(b))


def _swap_in(staging: Path, out: Path, token: str) -> None:
    """Make the complete folder ``staging`` the folder ``out``, replacing an old one whole."""
    if not os.path.lexists(out):
        os.rename(staging, out)
        return
    if not out.is_dir():
        raise InputError(f"{out} exists and is not a folder; choose another --out")
    if exchange(staging, out):          # staging now holds the old folder
        shutil.rmtree(staging)
        return
    ready, aside = _sibling(out, "ready", token), _sibling(out, "aside", token)
    os.rename(staging, ready)
    try:
        os.rename(out, aside)
        try:
            os.rename(ready, out)
        except BaseException:
            os.rename(aside, out)
            raise
    except BaseException:
        shutil.rmtree(ready, ignore_errors=True)
        raise
    shutil.rmtree(aside)


@contextlib.contextmanager
def replace_folder(out: str | os.PathLike) -> Iterator[Path]:
    """Yield an empty staging folder next to ``out``; on success it replaces ``out`` whole.

    The old folder is swapped out in one atomic step where Linux allows it
    (``renameat2(RENAME_EXCHANGE)``), else by two renames (old aside, new in), and then
    removed. On an exception the staging folder is removed and ``out`` is left as it was.
    What a killed run left next to ``out`` is recovered first (:func:`recover_folder`).
    A symbolic link ``out`` keeps pointing to the folder, which is replaced.
    """
    out = Path(os.path.realpath(out))
    out.parent.mkdir(parents=True, exist_ok=True)
    recover_folder(out)
    token = secrets.token_hex(4)
    staging = _sibling(out, "staging", token)
    staging.mkdir()
    try:
        yield staging
        for path in staging.rglob("*"):
            os.chmod(path, DIR_MODE if path.is_dir() else FILE_MODE)
        os.chmod(staging, DIR_MODE)
        _swap_in(staging, out, token)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise

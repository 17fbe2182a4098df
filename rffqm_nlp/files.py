"""Files on disk: TOML input, atomic writes, JSON without NaN, and whole-folder replacement.

Every file is written atomically (a temporary file in the target folder, then
:func:`os.replace`). A command that writes a folder of files writes them into a staging
folder next to it and replaces the output folder whole (:func:`replace_folder`): a kill at
any moment leaves either the complete old folder or the complete new one, and the next run
into the same place cleans up what the killed one left.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import json
import math
import os
import re
import secrets
import shutil
import sys
import tempfile
import tomllib
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .errors import InputError


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


FILE_MODE = 0o666 & ~_umask()
DIR_MODE = 0o777 & ~_umask()


# --------------------------------------------------------------------------- reading
def read_toml(path: str | os.PathLike, what: str = "file",
              error: type[InputError] = InputError) -> dict[str, Any]:
    """The tables of a TOML file; a missing or invalid file raises ``error`` naming ``what``
    (e.g. "design file") and the path."""
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise error(f"no such {what}: {path}") from None
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{what} {path} is not valid TOML: {exc}") from None


# --------------------------------------------------------------------------- single files
@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path next to ``path`` (same suffix); on success move it onto ``path``.

    On an exception the temporary file is removed and ``path`` is left untouched.
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=path.suffix)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, FILE_MODE)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def write_text(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically; returns the path."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


def jsonable(value: Any) -> Any:
    """``value`` with numpy arrays and scalars as lists and Python numbers, and objects with
    a ``to_dict`` method (Pattern, Fit, ...) as their dicts, recursively (mapping keys as
    strings); :class:`InputError` for anything JSON cannot hold."""
    if hasattr(value, "to_dict"):
        return jsonable(value.to_dict())
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Mapping):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if value is None or isinstance(value, (str, int, float, bool)):
        return value
    raise InputError(f"{value!r} ({type(value).__name__}) cannot be stored in JSON; use "
                     "numbers, strings, booleans, lists, dicts or numpy arrays")


def _non_finite(value: Any, where: str) -> str | None:
    """The place (``fit.rms``, ``history[3]``) of the first NaN or infinity in a
    :func:`jsonable` value, or None."""
    if isinstance(value, float) and not math.isfinite(value):
        return where or "the value"
    items = (value.items() if isinstance(value, dict)
             else enumerate(value) if isinstance(value, list) else ())
    for key, item in items:
        place = f"{where}[{key}]" if isinstance(key, int) else (f"{where}.{key}" if where
                                                                  else str(key))
        if found := _non_finite(item, place):
            return found
    return None


def write_json(path: str | os.PathLike, obj: Any, indent: int | None = None) -> Path:
    """Write ``obj`` (after :func:`jsonable`) as JSON to ``path`` atomically; returns the path.

    No file holds NaN or infinity: such a value raises :class:`InputError` naming where it
    is (e.g. ``fit.rms``), and nothing is written.
    """
    data = jsonable(obj)
    try:
        text = json.dumps(data, indent=indent, allow_nan=False)
    except ValueError:
        raise InputError(f"cannot write {path}: {_non_finite(data, '')} is not a finite "
                         "number (NaN or infinity); no file holds one") from None
    return write_text(path, text)


# --------------------------------------------------------------------------- output folders
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


_RENAMEAT2 = _renameat2()
_AT_FDCWD = -100
_RENAME_EXCHANGE = 2


def _exchange(a: Path, b: Path) -> bool:
    """Swap the folders ``a`` and ``b`` in one atomic step; False where the system or file
    system cannot (then nothing changed)."""
    if _RENAMEAT2 is None:
        return False
    if _RENAMEAT2(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
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
    if _exchange(staging, out):          # staging now holds the old folder
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

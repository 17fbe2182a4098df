"""Files on disk: TOML and JSON input, atomic writes, JSON without NaN, and whole-folder
replacement.

Every file is written atomically (a temporary file in the target folder, then
:func:`os.replace`). A command that writes a folder of files writes them into a staging
folder next to it and replaces the output folder whole (:func:`replace_folder`): a kill at
any moment leaves either the complete old folder or the complete new one, and the next run
into the same place cleans up what the killed one left.

Validation of the tables read from TOML (and of the same values given through the API) has
its one home here: a :class:`Key` says what a key allows, :func:`check_table` checks a table
against a dict of Keys, and every refusal is one :class:`InputError` line naming the key
(``[design] panels``) and what it allows, never quoting a string longer than a short name.
"""

from __future__ import annotations

import contextlib
import ctypes
import difflib
import errno
import json
import math
import os
import re
import secrets
import shutil
import stat
import sys
import tempfile
import tomllib
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass
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
#: Largest TOML file read (bytes): a design or study file is a few hundred bytes.
MAX_TOML_BYTES = 1 << 20
#: Largest JSON file read (bytes): a design result or FOLD file of the largest patterns
#: stays far below it.
MAX_JSON_BYTES = 512 << 20
_FILE_KINDS = ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
               (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
               (stat.S_ISSOCK, "a socket"))


def read_toml(path: str | os.PathLike, what: str = "file",
              error: type[InputError] = InputError) -> dict[str, Any]:
    """The tables of a TOML file; anything else raises ``error`` naming ``what`` (e.g.
    "design file") and the path, on one line.

    Refused before it is opened: a missing path, anything that is not a regular file (a
    folder, FIFO, device or socket) and files over :data:`MAX_TOML_BYTES`; after reading:
    text that is not UTF-8 and invalid TOML (by line and column; no message quotes the
    file's content).
    """
    try:
        text = _read_text(path, what, error, MAX_TOML_BYTES, "TOML")
    except FileNotFoundError:
        raise error(f"no such {what}: {path}") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{what} {path} is not valid TOML: {_toml_problem(exc)}") from None
    except RecursionError:
        raise error(f"{what} {path} nests its arrays or tables too deeply") from None


def read_json(path: str | os.PathLike, what: str = "file",
              error: type[InputError] = InputError) -> Any:
    """The value of a JSON file; anything else raises ``error`` naming ``what`` (e.g.
    "design result") and the path, on one line.

    Refused as by :func:`read_toml` (a missing path, a folder, FIFO, device or socket,
    files over :data:`MAX_JSON_BYTES`, text that is not UTF-8), invalid JSON (by line
    and column) and whole numbers of more than :data:`MAX_JSON_DIGITS` digits. NaN,
    Infinity and 1e999 are read as floats, for the reader of each kind of file to refuse
    naming their place (:func:`rffqm_nlp.design.results.check_numbers`).
    """
    try:
        text = _read_text(path, what, error, MAX_JSON_BYTES, "JSON")
    except FileNotFoundError:
        raise error(f"no {what} at {path}") from None
    try:
        return json.loads(text, parse_int=_bounded_int)
    except _TooManyDigits as exc:
        raise error(f"{what} {path} holds a whole number of {exc.args[0]} digits, more than "
                    f"the {MAX_JSON_DIGITS} a file of rffqm_nlp may hold") from None
    except json.JSONDecodeError as exc:
        raise error(f"{what} {path} is not valid JSON: {exc.msg} (at line {exc.lineno}, "
                    f"column {exc.colno})") from None
    except RecursionError:
        raise error(f"{what} {path} nests its arrays or objects too deeply") from None


#: Most digits of a whole number in a JSON file, below the 4300 past which Python refuses to
#: convert one (rffqm_nlp writes none over 20).
MAX_JSON_DIGITS = 4000


class _TooManyDigits(Exception):
    """A JSON whole number of more than :data:`MAX_JSON_DIGITS` digits."""


def _bounded_int(text: str) -> int:
    digits = len(text.lstrip("-"))
    if digits > MAX_JSON_DIGITS:
        raise _TooManyDigits(digits)
    return int(text)


def _read_text(path: str | os.PathLike, what: str, error: type[InputError], limit: int,
               language: str) -> str:
    """The UTF-8 text of the regular file ``path`` of at most ``limit`` bytes (a file of
    ``language``, e.g. "TOML"); FileNotFoundError passes through, every other refusal is
    ``error``. Nothing but a regular file is opened, and never blocking (a FIFO swapped in
    between the check and the open is refused too)."""
    try:
        _check_regular(os.stat(path), path, what, error, limit, language)
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
        with os.fdopen(fd, "rb") as fh:
            _check_regular(os.fstat(fh.fileno()), path, what, error, limit, language)
            data = fh.read(limit + 1)
    except FileNotFoundError:
        raise
    except (IsADirectoryError, NotADirectoryError):
        raise error(f"{what} {path} is not a file") from None
    except OSError as exc:
        raise error(f"cannot read {what} {path}: {exc.strerror or type(exc).__name__}") from None
    if len(data) > limit:
        raise error(f"{what} {path} is larger than the {_size(limit)} a {what} may have")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise error(f"{what} {path} is not UTF-8 text (byte {exc.start}); a {language} file "
                    "is UTF-8 text") from None


def _check_regular(st: os.stat_result, path: Any, what: str, error: type[InputError],
                   limit: int, language: str) -> None:
    """Refuse anything but a regular file of at most ``limit`` bytes."""
    if not stat.S_ISREG(st.st_mode):
        kind = next((name for test, name in _FILE_KINDS if test(st.st_mode)), "not a file")
        raise error(f"{what} {path} is {kind}, not a regular file; give a {language} file")
    if st.st_size > limit:
        raise error(f"{what} {path} has {st.st_size} bytes, more than the {_size(limit)} a "
                    f"{what} may have")


def _size(limit: int) -> str:
    """A byte count in KiB, or in MiB from 64 MiB on."""
    return f"{limit >> 20} MiB" if limit >= 64 << 20 else f"{limit >> 10} KiB"


def _toml_problem(exc: Exception) -> str:
    """tomllib's reason and position, with anything it quotes from the file left out."""
    text = " ".join(str(exc).split())
    match = re.search(r"\((at line \d+, column \d+|at end of document)\)$", text)
    reason = text[:match.start()] if match else text
    reason = re.sub(r"\(.*\)|'.*'|\".*\"", "...", reason).strip()
    return f"{reason} ({match[1]})" if match else reason


def named_path(root: str | os.PathLike, name: Any, key: str, trust: bool = False) -> Path:
    """The path ``name`` that a file names under ``key`` (e.g. "base"), relative to
    ``root``, the folder of the file that names it.

    A file from someone else opens nothing outside its own folder: unless ``trust``, a path
    that leaves ``root`` (absolute, through "..", or by a symbolic link) is refused in one
    :class:`InputError` line, and so is one that this system cannot open (a NUL byte, a
    name too long). No message quotes the path.
    """
    check_value(name, Key("string"), key)
    try:
        path = Path(root) / name
        inside = path.resolve().is_relative_to(Path(root).resolve())
    except (OSError, ValueError, RuntimeError):
        raise InputError(f"{key} must name a file, got {describe_value(name)}, which is no "
                         "path this system can open") from None
    if not inside and not trust:
        raise InputError(f"{key} names a file outside the folder of the file that names it "
                         f"({describe_value(name)}); move the file there, or pass --trust "
                         "(trust=True in the API) if you trust the file")
    return path


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


# --------------------------------------------------------------------------- validation
#: Names from a file that an error message may repeat: short, plain identifiers.
_SAFE_NAME = re.compile(r"[A-Za-z0-9_.+-]{1,32}")


@dataclass(frozen=True)
class Key:
    """How one value is checked (:func:`check_value`); a table's keys map to Keys
    (:func:`check_table`).

    ``kind`` is one of

    * "number": a finite number (int or float, never a boolean), as a float, within ``low``
      and ``high`` (exclusive where ``low_open``/``high_open``);
    * "whole": a whole number within ``low`` and ``high``, even if ``even``, as an int;
    * "choice": one of the strings ``choices``;
    * "bool": true or false; "string": a string; "scalar": a finite number or a string;
    * "list": a list (or tuple) of values each checked by ``item``, with exactly ``length``
      or at least ``least`` and at most ``most`` of them, as a tuple;
    * "table": a table checked by ``spec`` (:func:`check_table`), or, without ``spec``, whose
      every value ``item`` checks, as a dict.

    ``optional``: None is allowed too (in a file: the key left out); ``required``:
    :func:`check_table` refuses a table without this key; ``hint``: said after what is
    allowed, e.g. "(2N, 2M)".
    """

    kind: str
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    even: bool = False
    choices: tuple[str, ...] = ()
    item: "Key | None" = None
    length: int | None = None
    least: int = 0
    most: int | None = None
    spec: "Mapping[str, Key] | None" = None
    optional: bool = False
    required: bool = False
    hint: str = ""

    def allowed(self) -> str:
        """What this key allows, in words (e.g. "a finite number in (0, 1.5708)")."""
        text = {"number": "a finite number", "bool": "true or false", "string": "a string",
                "scalar": "a finite number or a string",
                "choice": "one of " + ", ".join(repr(c) for c in self.choices)}.get(self.kind)
        if self.kind == "whole":
            text = "an even whole number" if self.even else "a whole number"
        if self.kind == "list":
            count = (_items(self.length) if self.length is not None
                     else f"{self.least} to {_items(self.most)}" if self.most is not None
                     else f"at least {_items(self.least)}" if self.least else "items")
            text = f"a list of {count}" + (f", each {self.item.allowed()}" if self.item else "")
        if self.kind == "table":
            text = ("a table of " + ", ".join(self.spec) if self.spec else "a table" + (
                f" whose values are each {self.item.allowed()}" if self.item else ""))
        text += self._bounds()
        if self.optional:
            text += " or None (leave the key out)"
        return f"{text} {self.hint}" if self.hint else text

    def _bounds(self) -> str:
        if self.kind not in ("number", "whole"):
            return ""
        lo, hi = self.low, self.high
        if lo is not None and hi is not None:
            return (f" in {'(' if self.low_open else '['}{lo:g}, {hi:g}"
                    f"{')' if self.high_open else ']'}")
        if lo is not None:
            return f" {'>' if self.low_open else '>='} {lo:g}"
        if hi is not None:
            return f" {'<' if self.high_open else '<='} {hi:g}"
        return ""


def _items(count: int) -> str:
    return f"{count} item" if count == 1 else f"{count} items"


def describe_value(value: Any) -> str:
    """A value for an error message: its type, the number itself for numbers, a string only
    when it is a short plain name (so no message quotes a file's content)."""
    if value is None:
        return "None"
    if isinstance(value, (bool, np.bool_)):
        return f"{'true' if value else 'false'} (a boolean)"
    if isinstance(value, (int, np.integer)):
        value = int(value)
        if abs(value) < 10**15:
            return f"the whole number {value}"
        if abs(value).bit_length() < 14000:          # str() refuses over 4300 digits
            return f"a whole number of {len(str(abs(value)))} digits"
        digits = int(abs(value).bit_length() * math.log10(2)) + 1
        return f"a whole number of about {digits} digits"
    if isinstance(value, (float, np.floating)):
        return f"the number {float(value):g}"
    if isinstance(value, str):
        return (f"the string {value!r}" if _SAFE_NAME.fullmatch(value)
                else f"a string of {len(value)} characters")
    if isinstance(value, np.ndarray) and value.ndim == 0:
        return describe_value(value.item())
    if isinstance(value, (list, tuple, np.ndarray)):
        return f"a list of {_items(len(value))}"
    if isinstance(value, Mapping):
        return "a table"
    return f"a {type(value).__name__}"


def key_name(where: str, key: Any) -> str:
    """How a key is named in messages: ``[design]`` at the top of a file, ``[design] panels``
    in a table, ``[design] weights.position`` further down."""
    key = shown_name(key)
    if not where:
        return f"[{key}]"
    return f"{where} {key}" if where.endswith("]") else f"{where}.{key}"


def shown_name(key: Any) -> str:
    """A key (or another name from a file) for a message: itself when it is a short plain
    name, else only its length."""
    key = str(key)
    return key if _SAFE_NAME.fullmatch(key) else f"(a name of {len(key)} characters)"


def unknown_key(key: Any, known: Iterable[str] | Mapping[str, Key], where: str,
                is_table: bool = False) -> str:
    """The message for ``key`` (not in ``known``) in the table ``where`` ("" for the top of a
    file, where ``known`` Keys of kind "table" are named as [table]): the key and the
    closest known one, else every known one."""
    def named(name: str) -> str:
        table = not isinstance(known, Mapping) or known[name].kind == "table"
        return f"[{name}]" if not where and table else name

    names = list(known)
    close = difflib.get_close_matches(str(key), names, n=1)
    hint = (f"did you mean {named(close[0])}?" if close
            else "known: " + ", ".join(named(name) for name in names))
    if where:
        return f"unknown key {key_name(where, key)}; {hint}"
    what = (f"unknown table {key_name('', key)}" if is_table
            else f"unknown key {shown_name(key)} at the top of the file")
    return f"{what}; {hint}"


def check_table(table: Any, spec: Mapping[str, Key], where: str) -> dict[str, Any]:
    """The keys of ``table`` checked by ``spec`` (:func:`check_value`), each converted; no
    defaults are filled in. ``where`` names the table ("[design]"; "" for the tables of a
    file). An unknown key is refused naming the closest known one, and so is a table
    missing a required key; every refusal is one :class:`InputError` line naming the key
    and what it allows."""
    if not isinstance(table, Mapping):
        raise InputError(f"{where or 'the file'} must be a table, got {describe_value(table)}")
    for key in table:
        if key not in spec:
            raise InputError(unknown_key(key, spec, where, isinstance(table[key], Mapping)))
    for key, rule in spec.items():
        if rule.required and key not in table:
            raise InputError(f"{where or 'the file'} needs {shown_name(key)}: "
                             f"{rule.allowed()}")
    return {key: check_value(value, spec[key], key_name(where, key) if where or
                             spec[key].kind == "table" else shown_name(key))
            for key, value in table.items()}


def check_value(value: Any, key: Key, name: str, error: type[InputError] = InputError) -> Any:
    """``value`` checked against ``key`` and converted (floats, ints, tuples, dicts); else
    an ``error`` (:class:`InputError` or a subclass, e.g. SurfaceError) "<name> must be
    <what is allowed>, got <what it is>"."""
    if error is not InputError:
        try:
            return check_value(value, key, name)
        except InputError as exc:
            raise error(str(exc)) from None
    if not isinstance(key, Key):
        raise InputError(f"key must be a rffqm_nlp.files.Key, got {describe_value(key)}")
    if value is None and key.optional:
        return None
    if isinstance(value, np.ndarray) and value.ndim == 0:      # an API caller's NumPy scalar
        value = value.item()
    checked = _CHECKS[key.kind](value, key, name)
    if checked is _REFUSED:
        hint = ""
        if key.kind == "choice" and isinstance(value, str):
            close = difflib.get_close_matches(value, key.choices, n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
        raise InputError(f"{name} must be {key.allowed()}, got {describe_value(value)}{hint}")
    return checked


_REFUSED = object()


def _check_number(value: Any, key: Key, name: str) -> Any:
    if isinstance(value, (bool, np.bool_)) or not isinstance(
            value, (int, float, np.integer, np.floating)):
        return _REFUSED
    try:
        number = float(value)
    except OverflowError:
        return _REFUSED
    return number if math.isfinite(number) and _within(number, key) else _REFUSED


def _check_whole(value: Any, key: Key, name: str) -> Any:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        return _REFUSED
    value = int(value)
    if (key.even and value % 2) or not _within(value, key):
        return _REFUSED
    return value


def _within(value: float, key: Key) -> bool:
    if key.low is not None and (value <= key.low if key.low_open else value < key.low):
        return False
    return key.high is None or (value < key.high if key.high_open else value <= key.high)


def _check_list(value: Any, key: Key, name: str) -> Any:
    if isinstance(value, np.ndarray) and value.ndim == 1:
        value = value.tolist()
    if not isinstance(value, (list, tuple)):
        return _REFUSED
    if ((key.length is not None and len(value) != key.length) or len(value) < key.least
            or (key.most is not None and len(value) > key.most)):
        return _REFUSED
    if key.item is None:
        return tuple(value)
    return tuple(check_value(v, key.item, f"{name}[{i}]") for i, v in enumerate(value))


def _check_table(value: Any, key: Key, name: str) -> Any:
    if not isinstance(value, Mapping):
        return _REFUSED
    if key.spec is not None:
        return check_table(value, key.spec, name)
    for k in value:
        if not isinstance(k, str):
            raise InputError(f"{name} takes names as keys, got {describe_value(k)}")
    if key.item is None:
        return dict(value)
    return {k: check_value(v, key.item, key_name(name, k)) for k, v in value.items()}


_CHECKS: dict[str, Callable[[Any, Key, str], Any]] = {
    "number": _check_number,
    "whole": _check_whole,
    "choice": lambda v, k, n: v if isinstance(v, str) and v in k.choices else _REFUSED,
    "bool": lambda v, k, n: bool(v) if isinstance(v, (bool, np.bool_)) else _REFUSED,
    "string": lambda v, k, n: v if isinstance(v, str) else _REFUSED,
    "scalar": lambda v, k, n: (v if isinstance(v, str) else _check_whole(v, Key("whole"), n)
                               if isinstance(v, (int, np.integer))
                               else _check_number(v, Key("number"), n)),
    "list": _check_list,
    "table": _check_table,
}

"""Reading TOML and JSON files bounded in size (no FIFOs, devices or folders), and the paths
that a file names (:func:`named_path`)."""

from __future__ import annotations

import json
import os
import re
import stat
import tomllib
from pathlib import Path
from typing import Any

from ..errors import InputError
from .validation import Key, check_value, describe_value


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

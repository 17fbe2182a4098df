"""What the commands print: every message, path and name through
:func:`rffqm_nlp.errors.safe_text` (:func:`shown`) on the stderr :data:`console`, and the
package's errors as one red line and exit status 2 (:func:`user_errors`)."""

from __future__ import annotations

import re
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from ..errors import RffqmError, one_line, safe_text

#: Where the commands print messages, warnings and progress (stderr).
console = Console(stderr=True)


@contextmanager
def user_errors() -> Iterator[None]:
    """Turn the package's named errors, and the errors of a path no file can have (too
    long, a NUL character, characters the file system cannot encode), into a one-line
    reason and exit status 2."""
    try:
        yield
    except (RffqmError, OSError) as exc:
        _fail(one_line(exc))
    except ValueError as exc:
        if not _path_error(exc):
            raise
        _fail(f"a path no file can have: {one_line(exc)}")
    except KeyboardInterrupt:
        console.print("[bold red]interrupted[/]", highlight=False)
        raise typer.Exit(130) from None


def _fail(reason: str) -> None:
    console.print(f"[bold red]error:[/] {shown(reason)}", highlight=False, soft_wrap=True)
    raise typer.Exit(2) from None


def _path_error(exc: ValueError) -> bool:
    """Whether ``exc`` is what the os module raises for a path with a NUL character
    ("embedded null byte") or one it cannot encode (a lone surrogate)."""
    return (isinstance(exc, UnicodeEncodeError)
            or re.search(r"null (byte|character)", str(exc)) is not None)


def shown(text: object) -> str:
    """``text`` (a message, a path, a name from a file) as the commands print it: through
    :func:`rffqm_nlp.errors.safe_text`, rich markup escaped."""
    return escape(safe_text(str(text)))


def warn(message: str) -> None:
    """A yellow one-line warning on stderr."""
    console.print(f"[yellow]warning:[/] {shown(message)}", highlight=False, soft_wrap=True)


def wrote(*paths: Path) -> None:
    """"wrote <path> and <path>" on stderr."""
    console.print("wrote " + " and ".join(shown(p) for p in paths), highlight=False,
                  soft_wrap=True)


def quantity_table(title: str, rows: list[tuple[str, str]]) -> Table:
    """A two-column rich table of named quantities."""
    table = Table(title=shown(title))
    table.add_column("quantity")
    table.add_column("value", justify="right")
    for name, value in rows:
        table.add_row(shown(name), shown(value))
    return table

"""The ``rffqm`` command group: typer's own usage errors in one line, ``--version``, and
every command, registered in the order its help lists them."""

from __future__ import annotations

import sys

import typer
from typer.core import TyperGroup

from . import output
from .check_command import check_cmd
from .design_command import design
from .forward_commands import march, targets
from .make_command import make_cmd
from .mechanics_command import mechanics_cmd
from .options import PanelsCommand
from .output import shown
from .result_commands import export, fold_cmd, render, view_cmd
from .sweep_command import sweep_cmd


class _OneLineErrors(TyperGroup):
    """The command group: typer's own usage errors (an option not of its type, an unknown
    option or command, a missing argument) in one line too, "error: <typer's message>
    (<command> --help)", with typer's exit status 2."""

    def main(self, *args, standalone_mode: bool = True, **kwargs):
        if not standalone_mode:
            return super().main(*args, standalone_mode=False, **kwargs)
        try:
            code = super().main(*args, standalone_mode=False, **kwargs)
        except typer.TyperException as exc:
            if type(exc).__name__ == "NoArgsIsHelpError":    # `rffqm` alone: the help
                exc.show()
            else:
                ctx = getattr(exc, "ctx", None)
                where = f" ({ctx.command_path} --help)" if ctx is not None else ""
                output.console.print(f"[bold red]error:[/] "
                                     f"{shown(exc.format_message() + where)}",
                                     highlight=False, soft_wrap=True)
            sys.exit(getattr(exc, "exit_code", 2))
        except typer.Abort:
            output.console.print("[bold red]aborted[/]", highlight=False)
            sys.exit(1)
        sys.exit(code if isinstance(code, int) else 0)


app = typer.Typer(cls=_OneLineErrors, add_completion=False, no_args_is_help=True,
                  rich_markup_mode="markdown",
                  help="Forward and inverse design of rigidly and flat-foldable origami.")


def _version(value: bool) -> None:
    if value:
        from .._version import __version__

        typer.echo(f"rffqm-nlp {__version__}")
        raise typer.Exit()


@app.callback()
def _root(version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                       help="Print the version and exit.")) -> None:
    """rffqm: forward and inverse design of rigidly and flat-foldable origami."""


# the commands, in the order the help lists them
app.command(cls=PanelsCommand)(design)
app.command("check")(check_cmd)
app.command("make")(make_cmd)
app.command("sweep")(sweep_cmd)
app.command("fold")(fold_cmd)
app.command()(export)
app.command()(render)
app.command("view")(view_cmd)
app.command("mechanics")(mechanics_cmd)
app.command()(targets)
app.command()(march)

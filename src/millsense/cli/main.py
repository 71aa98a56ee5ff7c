"""The ``millsense`` command.

Every sub-command lives in its own module under :mod:`millsense.cli` and registers itself on
:data:`app`. User errors (:class:`millsense.core.errors.UserError`) print one line and exit with
status 2, never a traceback.
"""

from __future__ import annotations

import sys

from millsense.core.blas import default_to_one_thread

# before numpy loads: small matrices run best on one BLAS thread (decision 2004)
default_to_one_thread()

import typer  # noqa: E402
from numpy.linalg import LinAlgError as _LinAlgError  # noqa: E402
from rich.console import Console  # noqa: E402

from millsense.core.errors import UserError  # noqa: E402

app = typer.Typer(
    name="millsense",
    help="Sensorless monitoring and control of milling from CNC drive signals.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    # plain click help: flags without '<bool>', '[mm]' not eaten as markup (decision 0923)
    rich_markup_mode=None,
)

err_console = Console(stderr=True, highlight=False, soft_wrap=True)

#: Set by a command that has written, closed and joined everything it started (``batch``): the
#: process then leaves without the interpreter's teardown (decision 2007).
_fast_exit = False


def allow_fast_exit() -> None:
    """Called by a command whose outputs are all written and closed and whose threads and
    child processes are all joined: when it ends successfully as the ``millsense`` process,
    the exit handlers run and the process ends without tearing down its modules (0.3-0.4 s
    with numba, scipy, pyarrow, matplotlib and Dask loaded; decision 2007)."""
    global _fast_exit
    _fast_exit = True


@app.callback()
def _root() -> None:
    """Sensorless monitoring and control of milling from CNC drive signals."""


def _register_commands(only: str | None = None) -> None:
    """Import every ``millsense.cli.cmd_*`` module; each registers its commands on ``app``.

    ``only``: the sub-command about to run. Its module ``cmd_<only>`` (dashes as underscores)
    is imported alone when it registers that command; otherwise (a command living in a module
    of another name, a misspelt one, the top-level help) every module is. Importing all 18
    costs 0.4-0.6 s of start-up that a batch pays once per run (decision 2007)."""
    import importlib
    import pkgutil

    import millsense.cli as pkg

    if only:
        mod = f"cmd_{only.replace('-', '_')}"
        if any(info.name == mod for info in pkgutil.iter_modules(pkg.__path__)):
            importlib.import_module(f"{pkg.__name__}.{mod}")
            if only in _registered_names():
                return
    for info in pkgutil.iter_modules(pkg.__path__):
        if info.name.startswith("cmd_"):
            importlib.import_module(f"{pkg.__name__}.{info.name}")


def _registered_names() -> set[str]:
    """Names of the commands and command groups registered on ``app`` so far."""
    names = set()
    for c in app.registered_commands:
        fn = c.callback
        names.add(c.name or (fn.__name__.replace("_", "-") if fn is not None else ""))
    for g in app.registered_groups:
        names.add(g.name or (g.typer_instance.info.name if g.typer_instance else None) or "")
    return names


def _command(argv: list[str] | None) -> str:
    """The sub-command of ``argv`` (or of the process arguments) for a message."""
    args = sys.argv[1:] if argv is None else argv
    return next((a for a in args if not a.startswith("-")), "millsense")


def main(argv: list[str] | None = None) -> None:
    """Entry point: run the CLI, turning user errors into one line and exit status 2."""
    args = sys.argv[1:] if argv is None else argv
    _register_commands(None if not args or args[0].startswith("-") else args[0])
    try:
        # without standalone mode click *returns* the code of a `typer.Exit` (validate's
        # "a case failed" = 1) instead of raising it: pass it on as the exit status
        code = app(args=argv, standalone_mode=False)
        if isinstance(code, int) and code != 0:
            sys.exit(code)
    except UserError as exc:
        err_console.print(f"millsense: error: {exc}", markup=False)
        sys.exit(exc.exit_code)
    except typer.Exit as exc:
        sys.exit(exc.exit_code)
    except typer.Abort:
        err_console.print("millsense: aborted", markup=False)
        sys.exit(130)
    except OSError as exc:
        # a file the user named cannot be read or written (a directory, no such folder, no
        # permission, disk full): one line naming it, like any other user error
        where = f"{exc.filename}: " if exc.filename is not None else ""
        err_console.print(f"millsense: error: {where}{exc.strerror or exc}", markup=False)
        sys.exit(2)
    except MemoryError:
        # the work ceilings (millsense.core.budget) should refuse this first: one line anyway
        err_console.print(
            f"millsense: error: {_command(argv)}: out of memory; reduce the input (a shorter "
            "program or recording, a coarser --step-mm/--resolution-mm)",
            markup=False,
        )
        sys.exit(2)
    except (ArithmeticError, _LinAlgError) as exc:
        # a numerical failure the plausibility layer did not foresee (decision 0941): one line
        err_console.print(
            f"millsense: error: {_command(argv)}: numerical failure ({type(exc).__name__}: "
            f"{' '.join(str(exc).split())}); check the inputs' physical values",
            markup=False,
        )
        sys.exit(2)
    except Exception as exc:
        # Usage errors of the (vendored) click parser: duck-typed, as typer may vendor click.
        if hasattr(exc, "format_message") and hasattr(exc, "exit_code"):
            message = exc.format_message()
            if message:
                err_console.print(f"millsense: error: {message}", markup=False)
            sys.exit(2)
        raise
    if argv is None and _fast_exit:  # the process itself, not a caller in the same process
        import atexit
        import os

        sys.stdout.flush()
        sys.stderr.flush()
        atexit._run_exitfuncs()
        os._exit(0)

"""``obsfmu``: the parser of every subcommand and the entry point (one line and exit code 2 for any
user mistake: :class:`ParameterError`, :class:`SimulationError`, :class:`OutputError`, a refusal of the
file system; 128 + the signal when interrupted)."""

from __future__ import annotations

import argparse
import signal
import sys
from collections.abc import Callable

from ..campaign.cli import SUBCOMMAND as SWEEP
from .args import EXIT_USAGE, Parser
from .commands import SUBCOMMANDS as COMMANDS
from .stopping import install_handlers, interrupted_status, raise_if_terminated, raise_terminated, restore_handlers
from .subcommand import Subcommand

__all__ = ["main", "parser", "register", "SUBCOMMANDS"]

#: every subcommand by name: the project's, then any added with :func:`register`
SUBCOMMANDS: dict[str, Subcommand] = {command.name: command for command in [*COMMANDS, SWEEP]}


def register(name: str, help: str, configure: Callable[[argparse.ArgumentParser], None],
             handler: Callable[[argparse.Namespace], int], epilog: str | Callable[[], str] | None = None) -> None:
    """Add ``obsfmu NAME`` (an extension's subcommand); ``epilog`` (text after the options in ``--help``)
    may be a function, called when the parser is built."""
    if name in SUBCOMMANDS:
        raise ValueError(f"subcommand {name!r} registered twice")
    SUBCOMMANDS[name] = Subcommand(name, help, configure, handler, epilog)


def _version() -> str:
    """The installed distribution's version (``obsfmu --version``)."""
    from importlib.metadata import PackageNotFoundError, version
    try:
        return version("obsfmu")
    except PackageNotFoundError:
        return "unknown (not installed)"


def parser(only: str | None = None) -> argparse.ArgumentParser:
    """The parser of every subcommand; with ``only`` (a subcommand's name, or ``""`` for none) the arguments
    and epilog of that one alone are added (the others keep their name and help: ``obsfmu --help`` lists
    them), so that a command imports what its own arguments need and nothing else."""
    main_parser = Parser(prog="obsfmu", description="Adaptive state observers as FMI 2.0 and 3.0 co-simulation FMUs")
    main_parser.add_argument("--version", action="version", version=f"obsfmu {_version()}")
    commands = main_parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for command in SUBCOMMANDS.values():
        whole = only is None or command.name == only
        epilog = None if not whole else command.epilog() if callable(command.epilog) else command.epilog
        sub = commands.add_parser(command.name, help=command.help, description=command.help, epilog=epilog,
                                  formatter_class=argparse.RawDescriptionHelpFormatter)
        if whole:
            command.configure(sub)
        sub.set_defaults(func=command.handler)
    return main_parser


def _command(argv: list[str]) -> str:
    """The subcommand ``argv`` names (its first word not an option), or ``""``."""
    return next((word for word in argv if not word.startswith("-")), "")


#: the errors that are a user's mistake (one line, exit 2), by the module defining them; a module not imported
#: raised none, so only those already imported are caught (`obsfmu list` imports neither numpy nor the master)
_USER_ERRORS = {"obsfmu.observers.checks": "ParameterError", "obsfmu.fmus.master.errors": "SimulationError",
                "obsfmu.fmus.output": "OutputError"}
_BUILD_ERRORS = {"obsfmu.fmus.native": "NativeBuildError"}


def _imported(errors: dict[str, str]) -> tuple[type[BaseException], ...]:
    return tuple(getattr(sys.modules[module], name) for module, name in errors.items() if module in sys.modules)


def _silence_stdout() -> None:
    """Point standard output at the null device, so that the interpreter's last flush cannot fail again."""
    import os
    try:
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, sys.stdout.fileno())
    except (OSError, ValueError):
        pass


def main(argv: list[str] | None = None) -> int:
    """``obsfmu ...``; returns the exit code (2: a user mistake, 128 + the signal: interrupted)."""
    previous = install_handlers(raise_terminated, ignored_too=())
    try:
        argv = sys.argv[1:] if argv is None else argv
        args = parser(_command(argv)).parse_args(argv)
        status = args.func(args)
        raise_if_terminated()   # a signal some library swallowed still ends the command with 128 + the signal
        return status
    except SystemExit as exc:  # argparse: --help (0) or a bad argument (2, message already printed)
        return exc.code if isinstance(exc.code, int) else EXIT_USAGE
    except _imported(_USER_ERRORS) as exc:
        print(f"obsfmu: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except _imported(_BUILD_ERRORS) as exc:  # the machine lacks what building a binary needs (a compiler, a Windows wheel)
        print(f"obsfmu: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt as exc:  # Ctrl-C, or a Terminated
        print(f"\nobsfmu: interrupted ({exc or 'SIGINT'})", file=sys.stderr)
        return interrupted_status(exc)
    except BrokenPipeError:  # the reader went away (obsfmu show --fields | head -1): quiet, as SIGPIPE would end it
        _silence_stdout()
        return 128 + signal.SIGPIPE
    except OSError as exc:  # a refusal of the file system not checked beforehand: still one line
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"obsfmu: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return EXIT_USAGE
    finally:
        restore_handlers(previous)

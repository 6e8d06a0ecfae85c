"""One rule for every command: a value given empty on the command line is refused (exit 2).

``scipctl designate SOL --product "$P"`` with ``P`` unset passes ``--product ""``. Read as "not given" it
designated from another camera; read as a path, ``""`` is ``.`` and products went to the current folder. So an
option or argument whose value is empty or blank is bad input, whatever its type, before the command runs:
one ``scipctl: error:`` line naming the option, exit code 2, nothing written. Leaving the option out is how
to ask for its default.

:class:`NonEmptyCommand` is the command class every ``scipctl`` command is built with (``scipctl/cli.py``).
An empty environment variable (``SCIPCTL_PRODUCTS_DIR=``) still means "not set", as in click.
"""

from __future__ import annotations

from typing import Any

import typer
from typer.core import TyperCommand

from ..errors import InputError
from .output import EXIT_BAD_INPUT, error


def _is_blank(value: Any) -> bool:
    values = value if isinstance(value, (list, tuple)) else (value,)
    return any(isinstance(v, str) and not v.strip() for v in values)


def empty_value_error(param) -> InputError:
    """The error for ``param`` (a command's option or argument) given an empty value."""
    if getattr(param, "param_type_name", "") == "option":
        name = max(param.opts, key=len)
        return InputError(name, name.lstrip("-"), "empty: give a value, or leave the option out")
    name = param.metavar or param.name.upper()
    return InputError(name, "argument", "empty: give a value")


class NonEmptyCommand(TyperCommand):
    """A typer command that refuses an option or argument given as ``""`` or blanks (module docstring)."""

    def make_parser(self, ctx):
        parser = super().make_parser(ctx)
        parse = parser.parse_args
        params = self.get_params(ctx)

        def parse_args(args):
            opts, largs, order = parse(args)  # raw strings, before any conversion ("" would become Path("."))
            if not ctx.resilient_parsing:  # shell completion parses half-typed lines
                for param in params:
                    if param.name in opts and _is_blank(opts[param.name]):
                        error(str(empty_value_error(param)))
                        raise typer.Exit(EXIT_BAD_INPUT)
            return opts, largs, order

        parser.parse_args = parse_args
        return parser

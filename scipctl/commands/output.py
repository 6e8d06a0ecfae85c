"""What the commands print, and the exit codes.

* stdout carries the answer: one JSON document (``--json``, :func:`emit_json`) or the product itself;
* stderr carries everything for people: rich tables (:func:`stderr_console`), ``scipctl: note: ...`` lines
  (:func:`note`) and one ``scipctl: error: ...`` line on failure (:func:`guarded`).

Exit codes: :data:`EXIT_OK` 0 ok; :data:`EXIT_NO` 1 the answer is "no" (:class:`~scipctl.errors.CommandFailed`:
failure detected, rule broken, no reliable match); :data:`EXIT_BAD_INPUT` 2 bad input or usage
(:class:`~scipctl.errors.InputError`, a missing/unreadable file); 3 a bug (:data:`EXIT_BUG`); 130 interrupted
(SIGINT); 143 terminated (SIGTERM, as a batch system or ``timeout`` sends it). Both signals unwind the command, so
temporary outputs are removed and nothing half-written is left.
Import-light (the CLI loads this at start-up): rich is imported when a console is made.
"""

from __future__ import annotations

import errno
import functools
import json
import signal
import sys
import threading

import typer

from ..errors import CommandFailed, InputError
from ..jsonutil import strict_json

EXIT_OK, EXIT_NO, EXIT_BAD_INPUT, EXIT_BUG, EXIT_INTERRUPTED, EXIT_TERMINATED = 0, 1, 2, 3, 130, 143
EXIT_BROKEN_PIPE = 141  # 128 + SIGPIPE: the reader of stdout (or stderr) went away (`scipctl ... --json | head -1`)


class Terminated(BaseException):
    """SIGTERM arrived: raised in the main thread so that every ``finally`` and context manager runs (temporary
    files and folders are removed, a local Dask cluster is shut down), like KeyboardInterrupt for SIGINT."""


def _raise_terminated(signum, frame):
    raise Terminated()


def error(msg: str) -> None:
    """The one ``scipctl: error:`` line on stderr; nothing when stderr's reader has gone away (the exit code
    still says what happened)."""
    try:
        sys.stderr.write(f"scipctl: error: {msg}\n")
        sys.stderr.flush()
    except (BrokenPipeError, ValueError):  # closed pipe, or a closed stream
        _to_devnull(sys.stderr)


def _to_devnull(stream) -> None:
    """Point ``stream``'s file descriptor at /dev/null, so that the interpreter's final flush of a stream whose
    reader went away does not fail again."""
    import os

    try:
        os.dup2(os.open(os.devnull, os.O_WRONLY), stream.fileno())
    except (OSError, ValueError):
        pass


def note(msg: str) -> None:
    """One line on stderr for something the operator should know (e.g. where products went)."""
    sys.stderr.write(f"scipctl: note: {msg}\n")


def stderr_console():
    """The rich console for tables and progress: stderr; wide (160 columns) when stderr is not a terminal,
    so that logs of operations scripts keep whole table rows."""
    from rich.console import Console

    class _Console(Console):
        def on_broken_pipe(self) -> None:
            # rich's own exits 1 ("the answer is no"): raise instead, for guarded's exit 141
            self.quiet = True
            raise BrokenPipeError(errno.EPIPE, "stderr closed by its reader")

    con = _Console(stderr=True)
    if not con.is_terminal:
        con = _Console(stderr=True, width=160)
    return con


def emit_json(doc) -> None:
    """``doc`` as one JSON document on stdout (sorted keys, numpy values as plain numbers; a non-finite number is
    ``null``: strict JSON, readable by any parser)."""
    sys.stdout.write(json.dumps(strict_json(doc), indent=2, sort_keys=True, allow_nan=False) + "\n")


def guarded(fn):
    """Map exceptions to one-line errors and exit codes; never a traceback.

    A :class:`CommandFailed` with a payload still prints the payload as JSON when the command was called
    with ``json_out=True``."""

    @functools.wraps(fn)
    def wrapper(*a, **kw):
        main = threading.current_thread() is threading.main_thread()  # signal handlers live in the main thread
        previous = signal.signal(signal.SIGTERM, _raise_terminated) if main else None
        try:
            return fn(*a, **kw)
        except typer.Exit:
            raise
        except InputError as e:
            error(str(e))
            raise typer.Exit(EXIT_BAD_INPUT)
        except CommandFailed as e:
            if e.payload is not None and kw.get("json_out"):
                emit_json(e.payload)
            error(str(e))
            raise typer.Exit(EXIT_NO)
        except (FileNotFoundError, IsADirectoryError, NotADirectoryError, PermissionError) as e:
            error(f"{getattr(e, 'filename', '') or ''}: {e.strerror or e}")
            raise typer.Exit(EXIT_BAD_INPUT)
        except BrokenPipeError:
            # not a bug in scipctl: stdout's (or stderr's: `2>&1 | head`) reader closed the pipe. Point stdout at
            # /dev/null so that the interpreter's final flush does not fail again, and exit as a shell reports
            # SIGPIPE (error() gives up quietly when stderr is the closed one).
            _to_devnull(sys.stdout)
            error("stdout or stderr closed by its reader (broken pipe)")
            raise typer.Exit(EXIT_BROKEN_PIPE)
        except KeyboardInterrupt:
            error("interrupted")
            raise typer.Exit(EXIT_INTERRUPTED)
        except Terminated:
            error("terminated")
            raise typer.Exit(EXIT_TERMINATED)
        except Exception as e:  # a bug: still one line, but say it is ours
            error(f"internal error ({type(e).__name__}): {e}. Please report it with the command line.")
            raise typer.Exit(EXIT_BUG)
        finally:
            if main:
                signal.signal(signal.SIGTERM, previous)

    return wrapper

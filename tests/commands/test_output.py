"""scipctl/commands/output.py: exit codes, the one error line, JSON on stdout."""

import json

import numpy as np
import pytest
import typer

from scipctl.commands.output import EXIT_BAD_INPUT, EXIT_BUG, EXIT_NO, emit_json, guarded
from scipctl.errors import CommandFailed, InputError
from tests.commands.conftest import SAMPLE


def _raising(exc):
    @guarded
    def cmd(json_out=False):
        raise exc

    return cmd


@pytest.mark.parametrize("exc, code", [
    (InputError("p1", "field", "bad\nvalue"), EXIT_BAD_INPUT),
    (CommandFailed("no match"), EXIT_NO),
    (FileNotFoundError(2, "No such file or directory", "x.mcap"), EXIT_BAD_INPUT),
    (RuntimeError("oops"), EXIT_BUG),
])
def test_exception_becomes_exit_code_and_one_stderr_line(capsys, exc, code):
    with pytest.raises(typer.Exit) as e:
        _raising(exc)()
    out, err = capsys.readouterr()
    assert e.value.exit_code == code
    assert out == "" and err.startswith("scipctl: error: ") and err.count("\n") == 1


def test_command_failed_payload_goes_to_stdout_with_json(capsys):
    with pytest.raises(typer.Exit) as e:
        _raising(CommandFailed("no", payload={"ok": False}))(json_out=True)
    out, err = capsys.readouterr()
    assert e.value.exit_code == EXIT_NO and json.loads(out) == {"ok": False} and err.count("\n") == 1


def test_emit_json_writes_numpy_as_plain_numbers(capsys):
    emit_json({"b": np.float64(1.5), "a": np.arange(2)})
    out = capsys.readouterr().out
    assert json.loads(out) == {"a": [0, 1], "b": 1.5} and out.index('"a"') < out.index('"b"')


def test_emit_json_is_strict_json(capsys):
    """A non-finite number is null, at any depth and in numpy arrays: --json output is RFC 8259 JSON (designate's
    failed match used to print "uv_right": [NaN, NaN], a campaign's summary Infinity)."""
    emit_json({"x": float("nan"), "l": [1.0, float("inf"), (2, -float("inf"))], "a": np.array([np.nan, 1.0]),
               "n": {"m": np.float64("inf")}, "ok": True, "s": "NaN"})

    def refuse(c):
        raise ValueError(c)

    doc = json.loads(capsys.readouterr().out, parse_constant=refuse)
    assert doc == {"x": None, "l": [1.0, None, [2, None]], "a": [None, 1.0], "n": {"m": None}, "ok": True, "s": "NaN"}


def test_help_answers_to_h_and_lists_every_exit_code():
    from typer.testing import CliRunner

    from scipctl.cli import app

    runner = CliRunner()
    for args in (["-h"], ["--help"], ["designate", "-h"]):
        r = runner.invoke(app, args)
        assert r.exit_code == 0 and "Usage:" in r.stdout, args
    top = runner.invoke(app, ["-h"]).stdout
    for code in ("0 ok", "1 the answer is no", "2 bad input", "3 a bug", "130 interrupted", "143 terminated"):
        assert code in " ".join(top.split()), code


def test_sigterm_unwinds_the_command_removes_temporaries_and_exits_143(capsys, tmp_path):
    """SIGTERM (a batch system, `timeout`) killed the process where it stood: exit 143 with no message, and an
    ingest left its half-written temporary workspace behind. Now it unwinds like SIGINT."""
    import os
    import signal

    from scipctl.commands.output import EXIT_TERMINATED
    from scipctl.io.atomic import atomic_directory

    previous = signal.getsignal(signal.SIGTERM)

    @guarded
    def cmd(json_out=False):
        with atomic_directory(tmp_path / "ws") as tmp:
            (tmp / "half.png").write_bytes(b"x")
            os.kill(os.getpid(), signal.SIGTERM)  # delivered here, in the main thread
            (tmp / "never.png").write_bytes(b"x")

    with pytest.raises(typer.Exit) as e:
        cmd()
    out, err = capsys.readouterr()
    assert e.value.exit_code == EXIT_TERMINATED == 143
    assert out == "" and err == "scipctl: error: terminated\n"
    assert list(tmp_path.iterdir()) == []  # neither the workspace nor its temporary folder
    assert signal.getsignal(signal.SIGTERM) is previous  # the handler lives only while a command runs


def test_a_closed_stdout_is_exit_141_not_a_bug(capsys):
    # `scipctl ... --json | head -1`: the reader went away. Reported as "internal error ... please report it"
    # (exit 3) before, which broke pipefail scripts
    from scipctl.commands.output import EXIT_BROKEN_PIPE

    with pytest.raises(typer.Exit) as e:
        _raising(BrokenPipeError(32, "Broken pipe"))()
    _, err = capsys.readouterr()
    assert e.value.exit_code == EXIT_BROKEN_PIPE == 141
    assert err.startswith("scipctl: error: ") and err.count("\n") == 1 and "broken pipe" in err


def test_a_real_closed_pipe_exits_141_with_one_line(tmp_path):
    import subprocess
    import sys

    # the reader closes its end before scipctl writes: the write fails with EPIPE
    p = subprocess.Popen([sys.executable, "-m", "scipctl.cli", "info", str(SAMPLE), "--json"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    p.stdout.close()
    err = p.stderr.read().decode()
    assert p.wait(timeout=300) == 141, err
    assert err.count("\n") == 1 and "Traceback" not in err


def test_a_closed_stderr_exits_141_too(tmp_path):
    import subprocess
    import sys

    # `scipctl info SOL 2>&1 | head -1`: the tables go to stderr, whose reader went away. The handler then wrote
    # its error line to the closed stderr, failed again, and click exited 1 ("the answer is no")
    p = subprocess.Popen([sys.executable, "-m", "scipctl.cli", "info", str(SAMPLE)],
                         stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    p.stderr.close()
    assert p.wait(timeout=300) == 141

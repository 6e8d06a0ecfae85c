"""scipctl/commands/empty_values.py: every command refuses an option or argument given empty, before any work.

A script's ``--target "$T"`` with ``T`` unset passes ``""``; each command used to decide on its own (some took it
for "not given", paths took it for ``.``). The rule now lives in one command class; these tests walk every
command's every option and argument, so a new one is covered without a new test."""

import os

import pytest
import typer
from typer.testing import CliRunner

from scipctl.cli import app
from scipctl.commands.empty_values import NonEmptyCommand
from tests.commands.conftest import SAMPLE

runner = CliRunner()


def _commands():
    group = typer.main.get_command(app)
    ctx = typer.Context(group)
    return {name: group.get_command(ctx, name) for name in group.list_commands(ctx)}


def _valued_params():
    """(command, how to give the value, what the error line names) for every option that takes a value and every
    argument of every command."""
    cases = []
    for name, command in _commands().items():
        for param in command.params:
            if param.param_type_name == "option":
                if param.is_flag or param.name in ("help",):
                    continue
                flag = max(param.opts, key=len)
                cases.append(pytest.param(name, [flag], f"{flag}: {flag.lstrip('-')}: empty", id=f"{name} {flag}"))
            else:
                cases.append(pytest.param(name, [], f"{param.metavar}: argument: empty", id=f"{name} {param.metavar}"))
    return cases


def test_every_command_has_the_rule():
    commands = _commands()
    assert len(commands) >= 10  # ingest, info, synth, designate, simulate-handoff, trust-evidence, fit-trust, ...
    assert {name for name, c in commands.items() if not isinstance(c, NonEmptyCommand)} == set()


@pytest.mark.parametrize("blank", ["", "  "])
@pytest.mark.parametrize("command,before,needle", _valued_params())
def test_an_empty_value_is_refused_in_one_line_and_writes_nothing(tmp_path, monkeypatch, command, before, needle,
                                                                   blank):
    monkeypatch.chdir(tmp_path)  # an empty path used to be read as "." (the current folder)
    r = runner.invoke(app, [command, *before, blank])
    assert r.exit_code == 2, (r.stdout, r.stderr)
    assert r.stderr.splitlines() == [f"scipctl: error: {needle}: give a value" + (
        ", or leave the option out" if before else "")]
    assert r.stdout == ""
    assert os.listdir(tmp_path) == []


def test_the_rule_runs_before_the_other_values_are_read(tmp_path):
    # a real downlink and a valid pixel beside the empty option: the empty value alone is the error
    r = runner.invoke(app, ["designate", str(SAMPLE), "--camera", "pancam", "--pixel", "512.25,380.5", "--id", ""])
    assert r.exit_code == 2
    assert r.stderr == "scipctl: error: --id: id: empty: give a value, or leave the option out\n"


def test_an_empty_environment_variable_still_means_not_set(tmp_path, monkeypatch):
    # click's rule for environment variables: SCIPCTL_PRODUCTS_DIR= is "not set", not an empty value
    monkeypatch.setenv("SCIPCTL_PRODUCTS_DIR", "")
    r = runner.invoke(app, ["info", str(SAMPLE), "--json"])
    assert r.exit_code == 0, r.stderr


def test_a_non_empty_value_passes(tmp_path):
    r = runner.invoke(app, ["info", str(SAMPLE), "--products-dir", str(tmp_path / "p")])
    assert r.exit_code == 0, r.stderr

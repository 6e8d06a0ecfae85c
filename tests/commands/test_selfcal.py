"""commands/selfcal.py: the fits a command keeps in ``stereo_selfcal.json`` and the next command takes back (on a
copy of the bundled sol, with `scipctl designate`, which fits the one pancam pair it reads)."""

import json

import pytest
from typer.testing import CliRunner

from scipctl.cli import app
from scipctl.commands.selfcal import CACHE_PRODUCT

runner = CliRunner()
PIXEL = "512.25,380.5"  # the README's example pixel


@pytest.fixture
def fitted(monkeypatch):
    """One entry (the left image's shape) per pair the commands run in this process matched, i.e. fitted."""
    import scipctl.pipeline.stereo_selfcal as mod

    calls, real = [], mod.stereo_matches

    def counting(left_px, right_px, params):
        calls.append(left_px.shape)
        return real(left_px, right_px, params)

    monkeypatch.setattr(mod, "stereo_matches", counting)
    return calls


def _designate(sol, *extra):
    r = runner.invoke(app, ["designate", str(sol), "--camera", "pancam", "--pixel", PIXEL, "--json", *extra])
    assert r.exit_code == 0, r.output
    return json.loads(r.stdout)


def _cache(sol):
    return sol.parent / (sol.name + ".scipctl") / CACHE_PRODUCT


def test_a_second_command_takes_the_saved_fit_and_answers_the_same(sol, fitted):
    _cache(sol).unlink(missing_ok=True)
    first = _designate(sol, "--id", "a1")
    assert len(fitted) == 1
    doc = json.loads(_cache(sol).read_text())
    assert doc["format"] == 1 and len(doc["code"]) == 64 and len(doc["fits"]) == 1
    assert doc["provenance"]["tool"] == "scipctl" and doc["provenance"]["version"] and "command" in doc["provenance"]
    assert doc["provenance"]["inputs"]["downlink"]["sha256"]
    (key, entry), = doc["fits"].items()
    (fit1,) = first["provenance"]["stereo_selfcal"]
    assert entry["fit"] == {k: fit1[k] for k in entry["fit"]}
    assert (entry["left"], entry["right"]) == (fit1["left"], fit1["right"])
    second = _designate(sol, "--id", "a2")
    (fit2,) = second["provenance"]["stereo_selfcal"]
    assert len(fitted) == 1 and fit2 == fit1  # not fitted again; the record of the fit made
    for k in ("xyz_rover_m", "range_m", "range_sigma_m", "uv_right", "p_ok", "go"):
        assert second[k] == first[k], k  # the same fit, so the same stereo, to the last digit
    assert json.loads(_cache(sol).read_text())["fits"].keys() == {key}  # nothing new: not written again


@pytest.mark.parametrize("damage", ["not json {", '{"format": 99}', "fit"])
def test_a_damaged_or_foreign_cache_is_fitted_again_and_replaced(sol, damage, fitted):
    _cache(sol).unlink(missing_ok=True)
    reference = _designate(sol, "--id", "b0", "--replace")
    if damage == "fit":
        doc = json.loads(_cache(sol).read_text())
        for e in doc["fits"].values():
            e["fit"]["n_used"] = -1
        damage = json.dumps(doc)
    _cache(sol).write_text(damage)
    n = len(fitted)
    rec = _designate(sol, "--id", "b1", "--replace")
    assert len(fitted) == n + 1 and rec["xyz_rover_m"] == reference["xyz_rover_m"]
    doc = json.loads(_cache(sol).read_text())
    assert doc["format"] == 1 and all(e["fit"]["n_used"] >= 0 for e in doc["fits"].values())


def test_a_saved_fit_of_other_code_is_not_taken(sol, monkeypatch, fitted):
    import scipctl.pipeline.stereo_selfcal as mod

    _cache(sol).unlink(missing_ok=True)
    _designate(sol, "--id", "c0", "--replace")
    monkeypatch.setattr(mod, "fit_code_identity", lambda: "f" * 64)
    _designate(sol, "--id", "c1", "--replace")
    assert len(fitted) == 2
    doc = json.loads(_cache(sol).read_text())
    assert doc["code"] == "f" * 64 and len(doc["fits"]) == 1  # the other code's fits are dropped, not kept


def test_without_selfcal_nothing_is_saved(tmp_path):
    import shutil

    from tests.commands.conftest import SAMPLE

    sol = tmp_path / SAMPLE.name
    shutil.copy(SAMPLE, sol)
    rec = _designate(sol, "--no-stereo-selfcal")
    assert rec["provenance"]["stereo_selfcal"] is False and not _cache(sol).exists()


def test_a_folder_that_takes_no_products_leaves_the_command_as_it_was():
    """The fits only save time: a save refused (InputError, OSError) is not the command's failure."""
    from types import SimpleNamespace

    from scipctl.commands.selfcal import _keep_fits
    from scipctl.errors import InputError

    for exc in (InputError("x", "file", "cannot write"), OSError(28, "No space left on device")):
        def refuse(name, doc, exc=exc):
            raise exc

        source = SimpleNamespace(save_json=refuse, downlink=SimpleNamespace(source_sha256="0" * 64))
        _keep_fits(source, "c" * 64, {}, [])

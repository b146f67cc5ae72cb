"""`diagnose` is `hammer diagnose`: the same report on the same traces."""

import json

import numpy as np
import pytest

import hammer_monitor as hm


@pytest.fixture(scope="module")
def friction_traces(hammer, tmp_path_factory):
    """A hammer with the paper's friction at 4 and 7 bar, as `hammer simulate` writes it."""
    d = tmp_path_factory.mktemp("diag")
    paths = []
    for bar, seed in ((4, 5), (7, 6)):
        p = d / f"m{bar}.csv"
        hammer.run("simulate", "--supply-bar", bar, "--duration", 0.6, "--seed", seed, "--effect", "coulomb_friction", "--out", p)
        paths.append(p)
    return paths


def test_diagnose_names_the_same_effect_with_the_same_parameters_as_the_cli(hammer, friction_traces, tmp_path):
    a, b = friction_traces
    out = tmp_path / "cli"
    hammer.run("diagnose", "--measured", a, "--measured", b, "--fit-on", a, "--out", out)
    cli = json.loads((out / "report.json").read_text())
    report, waves = hm.diagnose([a, b], fit_on=[a], figures=True)
    assert report["verdict"]["effects"] == cli["verdict"]["effects"] == ["coulomb_friction"]
    assert report["verdict"]["params"] == cli["verdict"]["params"]
    # Everything else too, but the bookkeeping of the run: its time, and how
    # the simulations split over the effects (the threads share the work in
    # whatever order they get to it: two CLI runs differ there too; the total
    # does not).
    for r in (report, cli):
        r.pop("elapsed_s")
        for e in r["effects"]:
            e.pop("simulations")
    assert report == cli
    # The figures' waveforms: one mean cycle per operating point, the
    # measured one on the nominal model's time base; friction slows the
    # hammer, so the fitted model's cycle is the longer.
    assert [w["supply_bar"] for w in waves] == [4.0, 7.0]
    for w in waves:
        n = len(w["t_s"])
        assert n > 100 and len(w["stages"]) == n
        assert len(w["measured"]["p_rear_pa"]) == len(w["nominal"]["accel_mps2"]) == n
        assert len(w["fitted"]["p_rear_pa"]) > n


def test_a_trace_without_supply_pressure_is_the_clis_message(hammer, friction_traces, tmp_path):
    bare = tmp_path / "bare.csv"
    bare.write_bytes(friction_traces[0].read_bytes())  # no sidecar beside it
    with pytest.raises(ValueError) as e:
        hm.diagnose([bare])
    assert "supply pressure unknown" in str(e.value)
    assert str(e.value) == hammer.error("diagnose", "--measured", bare, "--out", tmp_path / "out")


def test_one_path_on_its_own_is_one_trace(hammer, friction_traces, tmp_path):
    """A string is iterable: its characters must not be read as paths."""
    bare = tmp_path / "bare.csv"
    bare.write_bytes(friction_traces[0].read_bytes())
    expected = hammer.error("diagnose", "--measured", bare, "--out", tmp_path / "out")
    for given in (str(bare), bare):
        with pytest.raises(ValueError) as e:
            hm.diagnose(given, fit_on=given)
        assert str(e.value) == expected


def test_your_own_model_as_an_fmu_is_the_clis_model_diagnosis(hammer, friction_traces, tmp_path):
    """`model=` is `hammer diagnose --model`: the project's own FMU (its map
    beside it), fitted to the same traces, gives the CLI's report, run in
    worker processes of this Python; and on the built-in model's path the
    same verdict and parameters (the FMU is that model)."""
    a, b = friction_traces
    fmu = tmp_path / "hammer.fmu"
    hammer.run("fmu", "--out", fmu)
    out = tmp_path / "cli"
    hammer.run("diagnose", "--measured", a, "--measured", b, "--fit-on", a, "--model", fmu, "--out", out)
    cli = json.loads((out / "report.json").read_text())
    report = hm.diagnose([a, b], fit_on=[a], model=fmu, threads=1)
    assert report["options"]["threads"] == 1
    assert report["model"]["name"] == cli["model"]["name"]
    assert report["model"]["guid"] == cli["model"]["guid"]
    assert report["verdict"]["effects"] == cli["verdict"]["effects"] == ["coulomb_friction"]
    assert report["verdict"]["params"] == cli["verdict"]["params"]
    builtin = hm.diagnose([a, b], fit_on=[a])
    assert builtin["verdict"]["params"] == report["verdict"]["params"]


def test_threads_must_be_one_or_more(friction_traces):
    a, b = friction_traces
    with pytest.raises(ValueError, match="threads: at least 1"):
        hm.diagnose([a, b], fit_on=[a], threads=0)
    with pytest.raises(ValueError, match="threads: at least 1, got -2"):
        hm.diagnose([a, b], fit_on=[a], threads=-2)


def test_a_missing_fmu_is_refused_naming_it(friction_traces, tmp_path):
    a, b = friction_traces
    missing = tmp_path / "nowhere.fmu"
    with pytest.raises(ValueError, match="nowhere.fmu"):
        hm.diagnose([a, b], fit_on=[a], model=missing)

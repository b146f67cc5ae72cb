"""`simulate` is `hammer simulate`: the same trace at the same seed."""

import json
import struct

import numpy as np
import pytest

import hammer_monitor as hm


def bits(a: np.ndarray) -> bytes:
    return np.ascontiguousarray(a, dtype="<f8").tobytes()


def test_simulate_equals_the_cli_at_the_same_seed(simulated):
    trace, truth = hm.simulate(5.0, 0.3, effects={"coulomb_friction": {"k_n_per_bar": 2.5}}, seed=11)
    cli = hm.read_trace(simulated)
    assert trace.column_names == cli.column_names
    assert trace.num_rows == cli.num_rows
    for name in cli.column_names:
        ours, theirs = trace.column(name).to_numpy(), cli.column(name).to_numpy()
        if name == "t_s":
            # The CSV writes time with 9 decimals.
            assert np.max(np.abs(ours - theirs)) <= 5e-10
        else:
            # Every other column at full precision: the same bits.
            assert bits(ours) == bits(theirs), name
    # The per-cycle truth is the sidecar's.
    sidecar = json.loads(simulated.with_suffix(".json").read_text())
    assert truth.num_rows >= 5
    energies = truth.column("impact_energy_j").to_pylist()
    assert all(2 < e < 8 for e in energies[1:])
    assert json.dumps(sidecar).count(repr(energies[-1])) >= 1


def test_the_seed_sets_the_noise_and_only_the_noise():
    a, _ = hm.simulate(5.0, 0.05, seed=1)
    b, _ = hm.simulate(5.0, 0.05, seed=1)
    c, _ = hm.simulate(5.0, 0.05, seed=2)
    assert bits(a.column("p_rear_pa").to_numpy()) == bits(b.column("p_rear_pa").to_numpy())
    assert bits(a.column("p_rear_pa").to_numpy()) != bits(c.column("p_rear_pa").to_numpy())
    # The truth (the solution) does not depend on the sensor noise.
    assert bits(a.column("x_m").to_numpy()) == bits(c.column("x_m").to_numpy())


def test_effects_as_cli_specs_or_a_mapping_are_the_same_run():
    a, ta = hm.simulate(6.0, 0.3, effects=["leakage:gap_m=30e-6"], seed=3)
    b, tb = hm.simulate(6.0, 0.3, effects={"leakage": {"gap_m": 30e-6}}, seed=3)
    assert bits(a.column("p_rear_pa").to_numpy()) == bits(b.column("p_rear_pa").to_numpy())
    assert ta.to_pylist() == tb.to_pylist()
    # The leak costs impact energy against the nominal hammer.
    _, nominal = hm.simulate(6.0, 0.3, seed=3)
    assert np.mean(ta.column("impact_energy_j").to_pylist()[1:]) < np.mean(nominal.column("impact_energy_j").to_pylist()[1:])

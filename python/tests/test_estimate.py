"""`estimate` is `hammer estimate`: the same records, field for field, bit for bit."""

import math
import shutil
import struct

import numpy as np
import pyarrow as pa
import pytest

import hammer_monitor as hm


def same(a, b) -> bool:
    """Equal as the JSON carries them: the same bits for numbers (NaN as null)."""
    if isinstance(a, float) or isinstance(b, float):
        if a is None or b is None:
            return a is b
        return struct.pack("<d", float(a)) == struct.pack("<d", float(b))
    return a == b


def assert_same_records(table: pa.Table, cli: list):
    rows = table.to_pylist()
    assert len(rows) == len(cli) > 0
    for i, (row, want) in enumerate(zip(rows, cli)):
        assert set(row) == set(want), f"record {i}: columns differ"
        for key, value in want.items():
            assert same(row[key], value), f"record {i}, {key}: {row[key]!r} != CLI's {value!r}"


def test_estimate_of_a_file_equals_the_cli_jsonl(hammer, simulated):
    cli = hammer.jsonl("estimate", simulated, "--format", "jsonl")
    table = hm.estimate(simulated)
    assert_same_records(table, cli)
    # Physically a run of the hammer: about 22 Hz, joules of impact energy, friction on.
    valid = [r for r in cli if r["valid"]]
    assert len(valid) >= 3
    assert all(15 < r["frequency_hz"] < 30 for r in valid)
    assert all(1 < r["impact_energy_j"] < 10 for r in valid)
    assert np.mean([r["friction_n"] for r in valid]) > 3


def test_columns_are_the_csv_columns_in_order(hammer, simulated):
    header = hammer.run("estimate", simulated, "--format", "csv").stdout.splitlines()[0]
    assert hm.estimate(simulated).column_names == header.split(",") == hm.estimate_columns()


CHAMBERS = [
    f"{chamber}_{name}"
    for chamber in ("front", "rear")
    for name in (
        "feed_s",
        "feed_uncertainty_s",
        "feed_x_m",
        "feed_p_rear_pa",
        "feed_p_front_pa",
        "closed_exponent",
        "closed_exponent_uncertainty",
        "feed_area_m2",
        "feed_area_uncertainty_m2",
    )
]


def test_the_chambers_are_float_columns_null_where_unread(hammer, simulated):
    # The chambers as a board reads them; where not read (the first cycle
    # has no start) NaN, null in the JSON, flagged; float64 columns, NaN in
    # NumPy, the same rows as the CLI's.
    cli = hammer.jsonl("estimate", simulated, "--format", "jsonl")
    table = hm.estimate(simulated)
    for name in CHAMBERS:
        assert name in table.column_names, name
        assert table.schema.field(name).type == pa.float64(), name
        values = table.column(name).to_numpy(zero_copy_only=False)
        unread = [r[name] is None for r in cli]
        assert np.array_equal(np.isnan(values), unread), name
    rows = table.to_pylist()
    assert sum("chambers_unread" not in row["flags"] for row in rows) >= len(rows) - 2, rows
    for row in rows:
        if "chambers_unread" in row["flags"]:
            assert all(row[name] is None for name in CHAMBERS), row


def test_supply_pressure_and_config_are_the_cli_flags(hammer, simulated, tmp_path):
    config = tmp_path / "hammer.toml"
    config.write_text("[estimator]\nimpact_threshold_mps2 = 3000.0\n")
    cli = hammer.jsonl("estimate", simulated, "--format", "jsonl", "--supply-bar", 4.5, "--config", config)
    assert_same_records(hm.estimate(simulated, config, supply_bar=4.5), cli)


def test_arrays_are_estimated_as_the_same_samples_in_a_file(hammer, simulated, tmp_path):
    # Without the simulator's sidecar both read the samples with the default hammer and sensors.
    bare = tmp_path / "bare.csv"
    shutil.copy(simulated, bare)
    trace = hm.read_trace(bare)
    cli = hammer.jsonl("estimate", bare, "--format", "jsonl")
    arrays = {name: trace.column(name).to_numpy() for name in ("t_s", "p_rear_pa", "p_front_pa", "accel_mps2")}
    assert_same_records(hm.estimate(**arrays), cli)
    assert_same_records(hm.estimate(trace), cli)
    # A pandas-like mapping of lists works too.
    assert_same_records(hm.estimate({k: list(v) for k, v in arrays.items()}), cli)


def test_read_trace_holds_the_files_columns(simulated):
    trace = hm.read_trace(simulated)
    assert trace.column_names[:4] == ["t_s", "p_rear_pa", "p_front_pa", "accel_mps2"]
    assert "x_m" in trace.column_names  # the simulator's truth columns
    t = trace.column("t_s").to_numpy()
    assert trace.num_rows == 30001
    assert np.allclose(np.diff(t), 10e-6, rtol=1e-4)
    # Gauge pressures of a running hammer at 5 bar: vented near 0, fed below the supply.
    rear = trace.column("p_rear_pa").to_numpy()
    assert rear.min() < 0.5e5 and 2e5 < rear.max() < 5.5e5

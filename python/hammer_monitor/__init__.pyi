"""Type stubs of hammer_monitor (units in the names: _s, _pa gauge, _mps2, _n, _j, _hz; supply in bar)."""

import os
from typing import Any, Mapping, Sequence, Union

import numpy as np
import numpy.typing as npt
import pyarrow as pa

PathLike = Union[str, os.PathLike[str]]
ArrayLike = Union[npt.ArrayLike, Sequence[float]]
EffectParams = Union[Mapping[str, float], bool, None]
Effects = Union[Mapping[str, EffectParams], Sequence[str], str, None]

class NoValidCycle(UserWarning):
    """Cycles closed but none is valid: `estimate` warns with the CLI's refusal and returns the flagged records."""

def estimate_columns() -> list[str]:
    """The columns of `hammer estimate --format csv`, in order."""

def read_trace(path: PathLike, map: PathLike | None = None) -> pa.Table:
    """A trace file (any format the CLI reads; `map`: the `[import]` TOML) as
    float64 columns t_s (s), p_rear_pa, p_front_pa (gauge Pa), accel_mps2 (m/s²), then the file's others."""

def estimate(
    trace: PathLike | pa.Table | Mapping[str, ArrayLike] | Any | None = None,
    config: PathLike | None = None,
    *,
    t_s: ArrayLike | None = None,
    p_rear_pa: ArrayLike | None = None,
    p_front_pa: ArrayLike | None = None,
    accel_mps2: ArrayLike | None = None,
    map: PathLike | None = None,
    supply_bar: float | None = None,
) -> pa.Table:
    """One row per record with the columns of `hammer estimate --format csv`
    and the values of `--format jsonl` (friction_n in N, impact_energy_j in J, frequency_hz in Hz, ...).
    Raises ValueError with the CLI's message on bad input."""

def simulate(
    supply_bar: float | None = None,
    duration: float | None = None,
    effects: Effects = None,
    config: PathLike | None = None,
    seed: int | None = None,
    *,
    dt: float | None = None,
    rtol: float | None = None,
    ideal_sensors: bool = False,
) -> tuple[pa.Table, pa.Table]:
    """`hammer simulate`: (trace with the CSV's columns, per-cycle truth).
    supply_bar in bar (gauge), duration and dt in s. Raises ValueError with the CLI's message."""

def diagnose(
    measured: Sequence[PathLike | tuple[PathLike, float | None]],
    reference: Sequence[PathLike | tuple[PathLike, float | None]] | None = None,
    fit_on: Sequence[PathLike] | None = None,
    config: PathLike | None = None,
    *,
    nominal_uncertainty: float = 0.2,
    figures: bool = False,
    model: PathLike | None = None,
    model_map: PathLike | None = None,
    model_time_limit_s: float = 60.0,
    threads: int | None = None,
) -> dict[str, Any] | tuple[dict[str, Any], list[dict[str, Any]]]:
    """`hammer diagnose`: report.json's content as a dict; with figures=True also the
    waveforms per operating point (t_s in s, pressures in Pa gauge, accel_mps2, velocity_mps).
    measured and reference take trace files or `hammer commission` folders.
    supply_bar in bar. model: your FMU (`hammer diagnose --model`), run in worker
    processes of this Python. threads: simulations (FMU instances) side by side, default
    the machine's cores. Raises ValueError with the CLI's message."""

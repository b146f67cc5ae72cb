"""hammer-monitor from Python: read traces, estimate per-cycle friction and
impact energy, simulate the pneumatic hammer and diagnose the sim-to-real gap, on the same library code the
``hammer`` CLI runs (a number returned here is the number the CLI prints).

Units are SI and in the names: ``_s`` seconds, ``_pa`` pascal (gauge unless
``_abs``), ``_mps2`` m/s², ``_n`` newton, ``_j`` joule, ``_hz`` hertz; supply
pressures are given in bar (``supply_bar``) as on the CLI.

Every refusal (a missing file, a malformed trace, an out-of-range parameter)
raises :class:`ValueError` carrying the CLI's message. Long calls release the
GIL and return on Ctrl-C with :class:`KeyboardInterrupt`.
"""

from __future__ import annotations

import json
import os
import warnings
from typing import Mapping, Sequence, Union

import numpy as np
import pyarrow as pa

from . import _native

__all__ = ["read_trace", "estimate", "simulate", "diagnose", "estimate_columns", "NoValidCycle"]

PathLike = Union[str, "os.PathLike[str]"]


def _path(p: PathLike | None) -> str | None:
    return None if p is None else os.fspath(p)


def _trace_table(columns: Mapping[str, bytes]) -> pa.Table:
    return pa.table({name: np.frombuffer(raw, dtype="<f8") for name, raw in columns.items()})


def estimate_columns() -> list[str]:
    """The columns of ``hammer estimate --format csv``, in order."""
    return list(_native.estimate_columns())


class NoValidCycle(UserWarning):
    """Cycles closed but none is valid: the CLI refuses such a trace (exit 2)
    with this message; ``estimate`` warns with it and returns the flagged
    records, whose ``flags`` say why. ``warnings.simplefilter("error",
    NoValidCycle)`` makes it a refusal here too."""


def _records_table(result: tuple[Sequence[str], str | None]) -> pa.Table:
    lines, no_valid = result
    if no_valid is not None:
        warnings.warn(no_valid, NoValidCycle, stacklevel=3)
    rows = [json.loads(line) for line in lines]
    names = estimate_columns()
    return pa.table({name: _column([r.get(name) for r in rows]) for name in names})


def _column(values: list) -> pa.Array:
    """A column of the records. The JSON's null is a NaN (the chambers'
    characteristics until read): a column null throughout is still float64,
    not Arrow's null type, and reads as NaN in NumPy and pandas."""
    if all(v is None for v in values):
        return pa.array(values, type=pa.float64())
    return pa.array(values)


def read_trace(path: PathLike, map: PathLike | None = None) -> pa.Table:
    """Read a trace file into a pyarrow Table, as every ``hammer`` command reads it.

    ``path`` is the project's CSV (``t_s, p_rear_pa, p_front_pa, accel_mps2``,
    its JSON sidecar beside it) or a recorder's file (delimited text, TDMS, MAT
    v5, WAV, Parquet) read through ``map``, a TOML file with the ``[import]``
    table (``--map`` of the CLI; docs/trace-format.md).

    Columns: ``t_s`` (s), ``p_rear_pa`` and ``p_front_pa`` (gauge Pa),
    ``accel_mps2`` (m/s²), then any further column of the file (a simulated
    trace's truth: ``x_m``, ``v_mps``, ...), all float64.
    """
    return _trace_table(_native.read_trace(os.fspath(path), _path(map)))


def _array(values, name: str) -> bytes:
    a = np.ascontiguousarray(np.asarray(values, dtype="<f8"))
    if a.ndim != 1:
        raise ValueError(f"{name}: expected a one-dimensional array, got shape {a.shape}")
    return a.tobytes()


def estimate(
    trace=None,
    config: PathLike | None = None,
    *,
    t_s=None,
    p_rear_pa=None,
    p_front_pa=None,
    accel_mps2=None,
    map: PathLike | None = None,
    supply_bar: float | None = None,
) -> pa.Table:
    """Per-cycle estimates: one row per record, the columns of ``hammer estimate --format csv``.

    ``trace`` is a path (read as ``hammer estimate TRACE`` reads it: any format,
    its sidecar's hammer and sensors, ``map`` for a recorder's file), or a
    table/DataFrame/mapping with the columns ``t_s`` (s), ``p_rear_pa``,
    ``p_front_pa`` (gauge Pa) and ``accel_mps2`` (m/s²); or give those four as
    numpy arrays by keyword. Arrays are read with ``config``'s hammer and
    sensors (the defaults without one) and must be sampled uniformly.

    ``config`` is the project's TOML file (``--config``); ``supply_bar`` the
    gauge supply pressure in bar (``--supply-bar``; default: the sidecar's).

    The values are those of ``hammer estimate --format jsonl``, bit for bit:
    friction in N (``friction_n``, with ``friction_sd_n``), impact energy in J,
    frequency in Hz, ... ; ``valid`` is a bool and ``flags`` the list of the
    record's flag names. A trace in which no impact cycle closes raises
    ValueError with the CLI's message, which names what its no-impact records blame;
    one whose cycles are all flagged warns with the CLI's message
    (:class:`NoValidCycle`) and returns them.
    """
    arrays = (t_s, p_rear_pa, p_front_pa, accel_mps2)
    if trace is None:
        if any(a is None for a in arrays):
            raise ValueError("estimate: give a trace (a path or a table) or all of t_s, p_rear_pa, p_front_pa, accel_mps2")
    elif isinstance(trace, (str, os.PathLike)):
        if any(a is not None for a in arrays):
            raise ValueError("estimate: give a trace path or arrays, not both")
        lines = _native.estimate_file(os.fspath(trace), _path(config), _path(map), supply_bar)
        return _records_table(lines)
    else:
        if isinstance(trace, pa.Table):
            trace = {name: trace.column(name).to_numpy() for name in trace.column_names}
        try:
            arrays = tuple(np.asarray(trace[name]) for name in ("t_s", "p_rear_pa", "p_front_pa", "accel_mps2"))
        except KeyError as e:
            raise ValueError(f"estimate: the trace has no column {e}: it needs t_s, p_rear_pa, p_front_pa, accel_mps2") from None
    if map is not None:
        raise ValueError("estimate: map reads a recorder's file; arrays are already in SI units")
    names = ("t_s", "p_rear_pa", "p_front_pa", "accel_mps2")
    raw = [_array(a, n) for a, n in zip(arrays, names)]
    lines = _native.estimate_arrays(*raw, _path(config), supply_bar)
    return _records_table(lines)


def _effect_specs(effects) -> list[str]:
    if effects is None:
        return []
    if isinstance(effects, str):
        return [effects]
    if isinstance(effects, Mapping):
        specs = []
        for name, params in effects.items():
            if params is None or params is True:
                specs.append(str(name))
            elif isinstance(params, Mapping):
                args = ",".join(f"{k}={float(v)!r}" for k, v in params.items())
                specs.append(f"{name}:{args}" if args else str(name))
            else:
                raise ValueError(f"effect {name}: expected a mapping of parameters, True or None, got {params!r}")
        return specs
    return [str(s) for s in effects]


def simulate(
    supply_bar: float | None = None,
    duration: float | None = None,
    effects=None,
    config: PathLike | None = None,
    seed: int | None = None,
    *,
    dt: float | None = None,
    rtol: float | None = None,
    ideal_sensors: bool = False,
) -> tuple[pa.Table, pa.Table]:
    """Simulate the hammer as ``hammer simulate`` does: (trace, per-cycle truth).

    ``supply_bar`` is the gauge supply pressure in bar (the paper runs 4–7),
    ``duration`` the simulated time in s (default 0.5), ``seed`` the sensor
    noise's seed (same seed, same trace), ``dt`` the output step in s (default
    10e-6), ``rtol`` the integrator's relative tolerance; ``config`` a TOML
    file as ``--config``. ``effects`` switches catalogued effects on: a mapping
    ``{"name": {"key": value}}`` (``True`` for the defaults), or a list of the
    CLI's ``NAME:key=value,...`` specs.

    The trace has the columns of the CSV ``hammer simulate --out`` writes
    (``t_s``, ``p_rear_pa``, ``p_front_pa``, ``accel_mps2``, then the truth
    columns ``x_m``, ``v_mps``, ...); the truth table one row per impact cycle
    (``t_impact_s``, ``impact_energy_j``, ``friction_cycle_n``, ...).
    """
    columns, truth = _native.simulate(
        supply_bar, duration, _effect_specs(effects), _path(config), seed, dt, rtol, ideal_sensors
    )
    cycles = json.loads(truth)
    truth_table = pa.Table.from_pylist(cycles) if cycles else pa.table({})
    return _trace_table(columns), truth_table


def _traces(items, what: str) -> list:
    # One path on its own is one trace (a string is iterable: its characters
    # are not paths).
    if isinstance(items, (str, bytes, os.PathLike)):
        items = [items]
    out = []
    for item in items or []:
        if isinstance(item, (str, os.PathLike)):
            out.append((os.fspath(item), None))
        else:
            try:
                path, bar = item
            except (TypeError, ValueError):
                raise ValueError(f"{what}: expected a path or (path, supply_bar), got {item!r}") from None
            out.append((os.fspath(path), None if bar is None else float(bar)))
    return out


def diagnose(
    measured,
    reference=None,
    fit_on=None,
    config: PathLike | None = None,
    *,
    nominal_uncertainty: float = 0.2,
    figures: bool = False,
    model: PathLike | None = None,
    model_map: PathLike | None = None,
    model_time_limit_s: float = 60.0,
    threads: int | None = None,
):
    """The sim-to-real gap diagnosis, as ``hammer diagnose`` runs it (docs/diagnosis.md).

    ``measured`` is one trace file or a list of them, each a path (its supply pressure from the
    sidecar) or ``(path, supply_bar)`` with the gauge supply pressure in bar,
    or folders ``hammer commission`` wrote (all their captures);
    ``reference`` likewise lists records of the same hammer when it was known
    sound (the change from them is diagnosed; a commissioning folder made
    with another calibration than the measured captures is refused as
    stale); ``fit_on`` the measured traces
    to fit on (default: the first; the others are held out). ``config`` is the
    nominal model's TOML file, ``nominal_uncertainty`` the relative standard
    deviation of the parameters the model is unsure of.

    Returns the report as a dict with the content of ``report.json`` (the
    verdict under ``"verdict"``: effects named, their fitted parameters). With
    ``figures=True`` returns ``(report, waves)``: per operating point the mean
    measured, nominal and fitted cycle (``t_s`` in s, pressures in Pa gauge,
    ``accel_mps2``, ``velocity_mps``) and the stage of each sample, as the
    CLI's figures draw them. A diagnosis takes seconds to minutes; it releases
    the GIL and returns on Ctrl-C.

    ``model`` is your own model as an FMI 2.0 co-simulation FMU, fitted in
    place of the built-in one (``hammer diagnose --model``, docs/your-model.md),
    with ``model_map`` its map (default: ``X.map.toml`` beside ``X.fmu``) and
    ``model_time_limit_s`` the longest one run may take. The FMU runs in
    worker processes of this Python (``sys.executable``): an FMU that
    crashes or hangs raises ``ValueError`` naming it, never this process.
    ``config`` still describes the measured hammer. ``threads`` is how many
    simulations, and so FMU instances (a tool's runtime-licence seats), run
    side by side (``--threads``; default: the machine's cores); the verdict
    is the same on any number.
    """
    report, waves = _native.diagnose(
        _traces(measured, "measured"),
        _traces(reference, "reference"),
        [path for path, _ in _traces(fit_on, "fit_on")],
        _path(config),
        float(nominal_uncertainty),
        bool(figures),
        _path(model),
        _path(model_map),
        float(model_time_limit_s),
        None if threads is None else int(threads),
    )
    report = json.loads(report)
    if not figures:
        return report
    points = json.loads(waves)
    for p in points:
        p["t_s"] = np.asarray(p["t_s"], dtype="f8")
        for key in ("measured", "nominal", "fitted"):
            if p[key] is not None:
                p[key] = {k: np.asarray(v, dtype="f8") for k, v in p[key].items()}
    return report, points

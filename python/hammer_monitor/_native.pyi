"""The compiled core (PyO3); use the functions of hammer_monitor instead."""

def estimate_columns() -> list[str]: ...
def read_trace(path: str, map: str | None = None) -> dict[str, bytes]: ...
def estimate_file(
    path: str, config: str | None = None, map: str | None = None, supply_bar: float | None = None
) -> tuple[list[str], str | None]: ...
def estimate_arrays(
    t_s: bytes, p_rear_pa: bytes, p_front_pa: bytes, accel_mps2: bytes, config: str | None = None, supply_bar: float | None = None
) -> tuple[list[str], str | None]: ...
def simulate(
    supply_bar: float | None = None,
    duration_s: float | None = None,
    effects: list[str] = ...,
    config: str | None = None,
    seed: int | None = None,
    output_step_s: float | None = None,
    rtol: float | None = None,
    ideal_sensors: bool = False,
) -> tuple[dict[str, bytes], str]: ...
def diagnose(
    measured: list[tuple[str, float | None]],
    reference: list[tuple[str, float | None]] = ...,
    fit_on: list[str] = ...,
    config: str | None = None,
    nominal_uncertainty: float = 0.2,
    figures: bool = False,
    model: str | None = None,
    model_map: str | None = None,
    model_time_limit_s: float = 60.0,
    threads: int | None = None,
) -> tuple[str, str | None]: ...
def fmu_worker() -> int: ...

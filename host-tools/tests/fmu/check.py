"""FMPy's side of host-tools/tests/fmu.rs: validates the FMU, simulates
each case with fmpy.simulate_fmu, and reruns one case through FMPy's
low-level FMU2Slave (instantiate, run, reset, run). Prints one JSON object;
the Rust test compares it with `hammer simulate`'s sidecars.

usage: check.py FMU CASES_JSON
CASES_JSON: {"name": {"stop": s, "start": {parameter: value}}, ...}
"""

import json
import struct
import sys

import numpy as np
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi2 import FMU2Slave
from fmpy.validation import validate_fmu

OUTPUT_INTERVAL = 10e-6


def impacts(result):
    """(count, last impact velocity, last period) at each new impact."""
    count = result["impact_count"]
    new = np.nonzero(np.diff(count))[0] + 1
    return [
        [int(count[i]), float(result["last_impact_velocity_mps"][i]), float(result["last_period_s"][i])]
        for i in new
    ]


def low_level_run(fmu, model, unzipped, case, slave):
    """One run through FMU2Slave; every output at every point, as bytes."""
    vr = {v.name: v for v in model.modelVariables}
    reals = [v.valueReference for v in model.modelVariables if v.causality == "output" and v.type == "Real"]
    ints = [v.valueReference for v in model.modelVariables if v.causality == "output" and v.type == "Integer"]
    slave.setupExperiment(startTime=0.0, stopTime=case["stop"])
    slave.enterInitializationMode()
    for name, value in case["start"].items():
        v = vr[name]
        if v.type == "Real":
            slave.setReal([v.valueReference], [float(value)])
        elif v.type == "Integer":
            slave.setInteger([v.valueReference], [int(value)])
        else:
            slave.setBoolean([v.valueReference], [bool(value)])
    slave.exitInitializationMode()
    out = bytearray()
    n = int(round(case["stop"] / OUTPUT_INTERVAL))
    t = 0.0
    for k in range(n + 1):
        out += struct.pack(f"<{len(reals)}d", *slave.getReal(reals))
        out += struct.pack(f"<{len(ints)}i", *slave.getInteger(ints))
        if k == n:
            break
        nxt = (k + 1) * OUTPUT_INTERVAL
        slave.doStep(currentCommunicationPoint=t, communicationStepSize=nxt - t)
        t = nxt
    slave.terminate()
    return bytes(out)


def main():
    fmu, cases = sys.argv[1], json.loads(sys.argv[2])
    report = {"problems": validate_fmu(fmu), "runs": {}}
    for name, case in cases.items():
        result = simulate_fmu(
            fmu,
            stop_time=case["stop"],
            relative_tolerance=1e-6,
            output_interval=OUTPUT_INTERVAL,
            start_values=case["start"],
            output=["impact_count", "last_impact_velocity_mps", "last_period_s"],
        )
        report["runs"][name] = {"samples": len(result), "impacts": impacts(result)}
    model = read_model_description(fmu)
    unzipped = extract(fmu)
    slave = FMU2Slave(
        guid=model.guid,
        unzipDirectory=unzipped,
        modelIdentifier=model.coSimulation.modelIdentifier,
        instanceName="reset",
    )
    slave.instantiate()
    case = cases[sys.argv[3]]
    first = low_level_run(fmu, model, unzipped, case, slave)
    slave.reset()
    second = low_level_run(fmu, model, unzipped, case, slave)
    slave.freeInstance()
    report["reset"] = {"bytes": len(first), "identical": first == second}
    print(json.dumps(report))


if __name__ == "__main__":
    main()

"""Two diagnose-bench outputs (bench.json) against each other: every case's
verdict (named effects) equal, and every number within a relative tolerance,
leaving out what counts time or names the model. Prints the largest
relative difference and where; exit 1 if a verdict or a non-number differs
or a number is off by more than the tolerance.

    python3 compare.py BUILTIN/bench.json FMU/bench.json [--tol 1e-6]
"""
import json
import sys

# Time, and the model's identity; and what the benchmark reads off the
# built-in model's own states beside the verdict (a valve delay's port
# shift, the heat exchanged and air leaked per cycle of a fitted heat
# exchange or leak): a foreign model has no such states to read.
SKIP = {
    "diagnose_s",
    "mean_diagnose_s",
    "elapsed_s",
    "simulations",
    "model",
    "port_shift_per_tau",
    "port_shift_error",
    "port_shift_within_15pct",
    "physical_sizes",
    "physical_within_15pct",
}


def walk(a, b, path, out):
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if k in SKIP:
                continue
            if k not in a or k not in b:
                out["other"].append(f"{path}/{k}: only in one")
                continue
            walk(a[k], b[k], f"{path}/{k}", out)
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            out["other"].append(f"{path}: {len(a)} items against {len(b)}")
            return
        for i, (x, y) in enumerate(zip(a, b)):
            walk(x, y, f"{path}[{i}]", out)
    elif isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool):
        d = abs(a - b) / max(abs(a), abs(b), sys.float_info.min)
        out["n"] += 1
        if d > out["worst"][0]:
            out["worst"] = (d, path)
    elif a != b:
        out["other"].append(f"{path}: {a!r} against {b!r}")


def main():
    args = sys.argv[1:]
    tol = 1e-6
    if "--tol" in args:
        i = args.index("--tol")
        tol = float(args[i + 1])
        del args[i : i + 2]
    a, b = (json.load(open(p)) for p in args)
    named = [(c["index"], c["named"], d["named"]) for c, d in zip(a["cases"], b["cases"])]
    differ = [n for n in named if n[1] != n[2]]
    out = {"n": 0, "worst": (0.0, ""), "other": []}
    walk(a, b, "", out)
    print(f"{len(named)} cases, {len(named) - len(differ)} with the same verdict")
    print(f"{out['n']} numbers compared; largest relative difference {out['worst'][0]:.3e} at {out['worst'][1] or '-'}")
    for line in out["other"][:20]:
        print("differs:", line)
    ok = not differ and not out["other"] and out["worst"][0] <= tol
    print("same within", tol if ok else f"{tol}: NO")
    sys.exit(0 if ok else 1)


main()

"""Issue 46's figures counted over both seeds: the variants FMU's structural
benchmark at seeds 7 and 8 (variants-fmu-structural-seed{7,8}/bench.json),
cases pooled, and beside it the built-in model on the same cases
(structural/ is seed 7, structural-seed8/ seed 8). Singles, each
waveform-only single, controls, pairs, parameters within 15 % and the
held-out energy error after the fit (mean over the cases with an effect),
as the issue asks them.

    python3 docs/diagnose-bench/both_seeds.py
"""
import json
import pathlib

HERE = pathlib.Path(__file__).resolve().parent
WAVEFORM_ONLY = ["leakage", "valve_delay", "heat_transfer", "supply_restriction"]
MODELS = {
    "through the variants FMU": ["variants-fmu-structural-seed7", "variants-fmu-structural-seed8"],
    "the built-in model, same cases": ["structural", "structural-seed8"],
}


def hidden(case):
    h = case["hidden"]
    if not isinstance(h, dict):
        return []
    out = []
    for v in h.values():
        out += v if isinstance(v, list) else [v]
    return out


def pooled(dirs):
    tot = {k: [0, 0] for k in ("singles", "controls", "pairs", "params_15pct")}
    each = {e: [0, 0] for e in WAVEFORM_ONLY}
    held_out = []
    for name in dirs:
        d = json.loads((HERE / name / "bench.json").read_text())
        print(f"  {name}: seed {d['options']['seed']}, {len(d['cases'])} cases")
        for key, field in (("singles", "single_right"), ("controls", "none_flagged"),
                           ("pairs", "pair_right"), ("params_15pct", "params_within_15pct")):
            tot[key] = [tot[key][0] + d[field][0], tot[key][1] + d[field][1]]
        for c in d["cases"]:
            h = hidden(c)
            if len(h) == 1 and h[0] in each:
                each[h[0]][1] += 1
                each[h[0]][0] += c["outcome"] == "Exact"
            if h and c.get("energy_error_after") is not None:
                held_out.append(c["energy_error_after"])
    for key, (a, b) in tot.items():
        print(f"  {key}: {a}/{b} ({100 * a / max(b, 1):.1f} %)")
    print("  waveform-only singles:", ", ".join(f"{e} {a}/{b}" for e, (a, b) in each.items()))
    print(f"  held-out energy error after the fit, mean over {len(held_out)} cases with an effect: "
          f"{sum(held_out) / len(held_out):.3f} %")


def main():
    for model, dirs in MODELS.items():
        print(model)
        pooled(dirs)


if __name__ == "__main__":
    main()

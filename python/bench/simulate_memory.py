"""How much memory `hammer_monitor.simulate` holds per simulated second,
against the table it returns (issue 48: it held 3.9x the table).

    python python/bench/simulate_memory.py [--seconds 4 8 16]

The last column, the memory each further simulated second costs, is the
figure to read (the table is 8.8 MB per simulated second at 10 µs).

Each figure comes from a fresh interpreter's peak resident set (ru_maxrss),
less that of one that simulated 10 ms (the package, numpy, pyarrow and their
allocators' pools: a fixed cost, not one per second). Prints the figures; it
asserts nothing (a figure to read, not a timed test).
"""

import argparse
import subprocess
import sys

CHILD = """
import resource, sys
import hammer_monitor as hm
seconds = float(sys.argv[1])
if seconds > 0:
    trace, truth = hm.simulate(4.0, seconds, seed=1)
    table = trace.nbytes
else:
    table = 0
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024, table)
"""


def peak(seconds: float) -> tuple[int, int]:
    out = subprocess.run([sys.executable, "-c", CHILD, str(seconds)], check=True, capture_output=True, text=True)
    rss, table = out.stdout.split()
    return int(rss), int(table)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, nargs="+", default=[4.0, 8.0, 16.0])
    args = ap.parse_args()
    base, _ = peak(0.01)
    print(f"interpreter after a 10 ms simulation: {base / 1e6:.1f} MB peak")
    print("simulated s   peak above it (MB)   table (MB)   peak / table   MB per further s")
    last = None
    for s in args.seconds:
        rss, table = peak(s)
        grown = rss - base
        slope = "" if last is None else f"{(grown - last[1]) / (s - last[0]) / 1e6:16.1f}"
        print(f"{s:11.1f}   {grown / 1e6:18.1f}   {table / 1e6:10.1f}   {grown / table:12.2f}   {slope}")
        last = (s, grown)


if __name__ == "__main__":
    main()

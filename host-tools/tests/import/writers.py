"""The same samples in each recorder format, written by that format's own
reference writer (host-tools/tests/import.rs runs this).

usage: writers.py NATIVE.csv OUTDIR

Reads the project's trace NATIVE.csv (t_s, p_rear_pa, p_front_pa,
accel_mps2 and truth columns) and writes into OUTDIR:
  npTDMS:      tdms_rate.tdms (wf_increment), tdms_time.tdms (a t_s channel)
  scipy:       mat_vectors.mat (t_s vector), mat_rate.mat (dt_s scalar)
  pyarrow:     arrow.parquet (Snappy, pyarrow's default)
  pandas:      recorder.csv in bar / g / ms, ';' and a decimal comma, a preamble
  wave:        sound.wav (3 channels, 16-bit PCM) and sound_native.csv: the
               project's trace of the same rounded values
"""
import sys
import wave

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import scipy.io
from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

native, out = sys.argv[1], sys.argv[2]
cols = {"t_s": [], "p_rear_pa": [], "p_front_pa": [], "accel_mps2": []}
with open(native) as f:
    header = f.readline().strip().split(",")
    idx = {n: header.index(n) for n in cols}
    for line in f:
        fields = line.strip().split(",")
        for n, i in idx.items():
            cols[n].append(float(fields[i]))
c = {n: np.array(v, dtype=np.float64) for n, v in cols.items()}
n = len(c["t_s"])
dt = 1e-5  # the simulator's default grid

signals = ["p_rear_pa", "p_front_pa", "accel_mps2"]
with TdmsWriter(f"{out}/tdms_rate.tdms") as w:
    w.write_segment(
        [RootObject({"recorder": "test"}), GroupObject("bench")]
        + [ChannelObject("bench", s, c[s], properties={"wf_increment": dt, "wf_start_offset": 0.0}) for s in signals]
    )
with TdmsWriter(f"{out}/tdms_time.tdms") as w:
    # Two segments: the second appends to the channels of the first.
    half = n // 2
    for a, b in [(0, half), (half, n)]:
        w.write_segment([ChannelObject("bench", s, c[s][a:b]) for s in ["t_s"] + signals])

scipy.io.savemat(f"{out}/mat_vectors.mat", {s: c[s] for s in ["t_s"] + signals})
scipy.io.savemat(f"{out}/mat_rate.mat", {**{s: c[s] for s in signals}, "dt_s": dt, "t0_s": 0.0})

pq.write_table(pa.table({s: c[s] for s in ["t_s"] + signals}), f"{out}/arrow.parquet")

df = pd.DataFrame(
    {
        "Zeit [ms]": c["t_s"] * 1e3,
        "P hinten [bar]": c["p_rear_pa"] / 1e5,
        "P vorne [bar]": c["p_front_pa"] / 1e5,
        "Beschl. [g]": c["accel_mps2"] / 9.80665,
    }
)
with open(f"{out}/recorder.csv", "w", newline="") as f:
    f.write("Recorder: WaveLab 3\nDate;2026-11-27\n\n")
    df.to_csv(f, sep=";", decimal=",", index=False)

# WAV: 16-bit codes of full scales 10 bar, 10 bar, 2000 m/s²; the native
# trace of the same rounded values, computed as the reader scales them.
full = {"p_rear_pa": 10.0, "p_front_pa": 10.0, "accel_mps2": 2000.0}
unit = {"p_rear_pa": 1e5, "p_front_pa": 1e5, "accel_mps2": 1.0}
si_full = {s: full[s] * unit[s] for s in signals}
codes = {s: np.clip(np.round(c[s] / si_full[s] * 32768), -32768, 32767).astype("<i2") for s in signals}
frames = np.stack([codes[s] for s in signals], axis=1).tobytes()
with wave.open(f"{out}/sound.wav", "wb") as w:
    w.setnchannels(3)
    w.setsampwidth(2)
    w.setframerate(100000)
    w.writeframes(frames)
with open(f"{out}/sound_native.csv", "w") as f:
    f.write("t_s,p_rear_pa,p_front_pa,accel_mps2\n")
    for i in range(n):
        v = [int(codes[s][i]) / 32768 * full[s] * unit[s] for s in signals]
        f.write(f"{i / 100000:.9f},{v[0]!r},{v[1]!r},{v[2]!r}\n")

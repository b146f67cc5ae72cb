"""Bad input raises ValueError with the CLI's message, never a crash of the interpreter."""

import json
import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

import hammer_monitor as hm


def test_a_missing_trace_is_the_clis_message(hammer, tmp_path):
    missing = tmp_path / "missing.csv"
    with pytest.raises(ValueError) as e:
        hm.estimate(missing)
    assert str(e.value) == hammer.error("estimate", missing)
    with pytest.raises(ValueError) as e:
        hm.read_trace(missing)
    assert str(e.value) == hammer.error("estimate", missing)


def test_a_malformed_trace_is_the_clis_message(hammer, tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("t_s,p_rear_pa,p_front_pa,accel_mps2\n0,1,2,3\n0.00001,1,two,3\n")
    with pytest.raises(ValueError) as e:
        hm.estimate(bad)
    assert "not a finite number" in str(e.value)
    assert str(e.value) == hammer.error("estimate", bad)


def test_a_malformed_config_is_the_clis_message(hammer, simulated, tmp_path):
    config = tmp_path / "bad.toml"
    config.write_text("[estimator]\nimpact_threshold_mps2 = \"high\"\n")
    with pytest.raises(ValueError) as e:
        hm.estimate(simulated, config)
    assert str(e.value) == hammer.error("estimate", simulated, "--config", config)


def test_an_unknown_effect_is_the_clis_message(hammer):
    with pytest.raises(ValueError) as e:
        hm.simulate(5.0, 0.05, effects={"no_such_effect": True})
    assert "unknown effect" in str(e.value)
    assert str(e.value) == hammer.error("simulate", "--duration", 0.05, "--effect", "no_such_effect")


def test_bad_arrays_are_refused_not_crashed():
    t = np.arange(1000) * 1e-5
    with pytest.raises(ValueError, match="different lengths"):
        hm.estimate(t_s=t, p_rear_pa=np.zeros(1000), p_front_pa=np.zeros(999), accel_mps2=np.zeros(1000))
    with pytest.raises(ValueError, match="not uniform"):
        jitter = t.copy()
        jitter[500] += 3e-6
        hm.estimate(t_s=jitter, p_rear_pa=np.zeros(1000), p_front_pa=np.zeros(1000), accel_mps2=np.zeros(1000))
    with pytest.raises(ValueError):
        hm.estimate(t_s=t[:1], p_rear_pa=[0.0], p_front_pa=[0.0], accel_mps2=[0.0])
    with pytest.raises(ValueError, match="out of range"):
        hm.simulate(99.0, 0.05)


def test_ctrl_c_interrupts_a_long_simulation():
    # A minute of simulated time takes several seconds; Ctrl-C returns at once.
    script = textwrap.dedent(
        """
        import signal, sys, time, hammer_monitor as hm
        # A child started from a background job inherits SIGINT ignored, and
        # Python then installs no handler: the test is of the library's
        # polling, so the default handler is put back.
        signal.signal(signal.SIGINT, signal.default_int_handler)
        print("started", flush=True)
        try:
            hm.simulate(5.0, 60.0)
        except KeyboardInterrupt:
            print("interrupted", flush=True)
            sys.exit(0)
        print("finished", flush=True)
        """
    )
    p = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "started"
    time.sleep(0.5)
    sent = time.monotonic()
    p.send_signal(signal.SIGINT)
    out, _ = p.communicate(timeout=60)
    took = time.monotonic() - sent
    assert out.strip() == "interrupted"
    assert p.returncode == 0
    assert took < 2.0, f"the interrupt took {took:.1f} s"


def test_a_trace_without_an_impact_is_the_clis_message(hammer, tmp_path):
    # A hammer that does not run: 0.2 s of vented chambers and a still piston.
    t = np.arange(20000) * 1e-5
    still = tmp_path / "still.csv"
    rows = np.column_stack([t, np.full_like(t, 200.0), np.full_like(t, -150.0), np.full_like(t, 0.5)])
    np.savetxt(still, rows, delimiter=",", header="t_s,p_rear_pa,p_front_pa,accel_mps2", comments="", fmt="%.9g")
    with pytest.raises(ValueError) as e:
        hm.estimate(still)
    assert "no impact cycle in 20000 samples" in str(e.value)
    assert str(e.value) == hammer.error("estimate", still, "--format", "jsonl")
    with pytest.raises(ValueError, match="arrays: no impact cycle in 20000 samples"):
        hm.estimate(hm.read_trace(still))


def test_a_stale_commissioning_record_is_the_clis_message(hammer, tmp_path):
    """Commissioning folders read as the CLI reads them: a record made
    before a recalibration is refused as stale, with the CLI's words."""
    ref, now = tmp_path / "ref", tmp_path / "now"
    for out in (ref, now):
        hammer.run("commission", "--demo", "--native", "--supply-bar", "4", "--cycles", "3", "--out", out)
    side = now / "4.0bar" / "cycle-000.json"
    sidecar = json.loads(side.read_text())
    sidecar["calibration_hash"] = 12345
    side.write_text(json.dumps(sidecar))
    with pytest.raises(ValueError) as e:
        hm.diagnose([now], reference=[ref])
    assert "stale" in str(e.value)
    assert str(e.value) == hammer.error("diagnose", "--measured", now, "--reference", ref, "--out", tmp_path / "d")


def test_no_valid_cycle_warns_with_the_clis_message(hammer, simulated, tmp_path):
    """The CLI refuses a trace whose cycles are all flagged (exit 2); the
    package warns with the same message and still returns the records."""
    bare = tmp_path / "bare.csv"
    bare.write_bytes(simulated.read_bytes())  # no sidecar: the config's hammer reads it
    short = tmp_path / "short.toml"
    # A piston that travels 32 mm: the hammer's 43 mm strokes are beyond it.
    short.write_text("[hammer]\nimpact_position_m = 0.032\n")
    expected = hammer.error("estimate", bare, "--config", short, "--supply-bar", 5)
    with pytest.warns(hm.NoValidCycle) as w:
        table = hm.estimate(bare, short, supply_bar=5.0)
    assert [str(x.message) for x in w if x.category is hm.NoValidCycle] == [expected]
    assert table.num_rows > 0 and not any(table.column("valid").to_pylist())
    trace = hm.read_trace(bare)
    arrays = {k: trace.column(k).to_numpy() for k in ("t_s", "p_rear_pa", "p_front_pa", "accel_mps2")}
    with pytest.warns(hm.NoValidCycle, match="arrays: no valid cycle among"):
        hm.estimate(config=short, supply_bar=5.0, **arrays)

"""Graphs on the wall clock from Python (`nanomotion rt` without files)."""

import numpy as np
import pytest

import nanomotion as nm


def quickstart(root, kp: str = "3.1416e7") -> nm.Graph:
    """The quickstart, scored from the start (its runs here are 10–50 ms)."""
    text = (root / "examples/quickstart.yaml").read_text()
    text = text.replace("from_s: 0.5", "from_s: 0.0").replace("kp: 3.1416e7", f"kp: {kp}")
    return nm.Graph(yaml=text, origin="quickstart.yaml")


def test_rt_with_catch_up_logs_what_run_logs_bit_for_bit(root):
    # Every tick runs under catch-up, so the graph's logs are the simulation's:
    # the wall clock changes when a tick runs, never what it computes.
    g = quickstart(root)
    offline = g.run(duration=0.05)
    r = g.rt(duration=0.05, allow_soft=True, overrun="catch-up")
    assert isinstance(r, nm.RtResult)
    assert set(r.signals) == set(offline.signals)
    for name, x in offline.signals.items():
        assert np.array_equal(r.signals[name], x), name
    assert r.scores == offline.scores
    # The timing report: one tick per base period of the 0.05 s.
    t = r.timing
    assert t["ticks"] == round(0.05 * g.base_rate_hz)
    assert t["rate_hz"] == g.base_rate_hz
    assert t["overrun_policy"] == "catch-up"
    assert t["missed_ticks"] == 0
    assert t["wakeup_latency"]["count"] == t["ticks"]
    assert t["wakeup_latency"]["p50_ns"] <= t["wakeup_latency"]["max_ns"]
    # At least the graph's duration of wall time went by (ticks on a grid of
    # period T from the first).
    assert r.wall_s >= (t["ticks"] - 1) / g.base_rate_hz


def test_rt_refuses_an_unstable_loop_before_it_starts(root):
    g = quickstart(root, kp="3.1416e8")
    with pytest.raises(nm.GateError, match="loop `pi` is unstable"):
        g.rt(duration=0.01, allow_soft=True)
    r = g.rt(duration=0.01, allow_soft=True, allow_unproven=True)
    assert any("allow_unproven" in line for line in r.stability_gate)
    assert r.timing["ticks"] == round(0.01 * g.base_rate_hz)


def test_rt_bad_settings_raise_naming_the_fix(root):
    g = nm.load(root / "examples/quickstart.yaml")
    with pytest.raises(nm.GraphError, match="catch-up"):
        g.rt(duration=0.01, allow_soft=True, overrun="later")
    with pytest.raises(nm.GraphError, match="1–99"):
        g.rt(duration=0.01, allow_soft=True, priority=0)

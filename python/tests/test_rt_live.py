"""Loops in the background from Python: live parameter updates
(`RtRun.set`, judged as `set BLOCK.PARAM=VALUE` on `nanomotion rt`'s
standard input is) and a plant in another process (`device="shm:NAME"`)."""

import _thread
import gc
import math
import os
import subprocess
import threading
import time

import numpy as np
import pytest

import nanomotion as nm

# y = k·1 at 1 kHz: the logged k.y is the gain itself, tick by tick.
GAIN = """
base_rate_hz: 1000
duration_s: {duration}
blocks:
  - {{ name: one, type: constant, value: 1.0 }}
  - {{ name: k, type: gain, k: 2.0 }}
connections:
  - {{ from: one.y, to: k.u }}
log: [k.y]
"""


def gain_graph(duration: float) -> nm.Graph:
    return nm.Graph(yaml=GAIN.format(duration=duration), origin="gain.yaml")


def quickstart(root) -> nm.Graph:
    """The quickstart, scored from the start (its runs here are 0.3 s)."""
    text = (root / "examples/quickstart.yaml").read_text().replace("from_s: 0.5", "from_s: 0.0")
    return nm.Graph(yaml=text, origin="quickstart.yaml")


def wait_for_ticks(h: nm.RtRun, ticks: int, timeout_s: float = 30.0) -> None:
    """Until the loop's status reports at least `ticks` ticks."""
    end = time.monotonic() + timeout_s
    while h.status()["ticks"] < ticks:
        assert h.running, "the loop ended before the update"
        assert time.monotonic() < end, f"no {ticks} ticks in {timeout_s} s: {h.status()}"
        time.sleep(0.005)


def test_a_gain_set_while_the_loop_runs_holds_from_the_tick_it_took_effect_at():
    g = gain_graph(duration=1.0)
    h = nm.rt_start(g, allow_soft=True, overrun="catch-up")
    assert h.live_params == ["k.k"]
    assert h.device == "none"
    wait_for_ticks(h, 200)
    h.set("k.k", 3.0)
    r = h.wait()
    assert not h.running
    (u,) = h.status()["updates"]
    assert (u["path"], u["value"]) == ("k.k", 3.0)
    tick = u["tick"]
    assert u["t_s"] == tick / 1000.0
    # Sent after 200 ticks had run, before the last one.
    assert 200 <= tick < 1000
    y = r.signals["k.y"]
    assert y.shape == (1000,)
    # Every tick before it computed with k = 2, every one from it with k = 3.
    assert np.all(y[:tick] == 2.0)
    assert np.all(y[tick:] == 3.0)
    assert r.timing["param_updates"] == 1
    assert r.timing["stop"] == "completed"
    # The handle returns the same result again.
    assert h.wait() is r and h.stop() is r and h.result is r


def test_a_pi_gain_set_mid_run_parts_the_run_from_the_simulation_at_its_tick(root):
    # Under catch-up every tick runs, so before the update the loop's logs are
    # the simulation's bit for bit; the PI (4 kHz, base 40 kHz) computes its
    # first sample with the new k_p at the first of its ticks at or after the
    # update's tick, and from there the drive differs.
    g = quickstart(root)
    offline = g.run(duration=0.3)
    h = g.rt_start(duration=0.3, allow_soft=True, overrun="catch-up")
    assert h.live_params == ["pi.kp", "pi.zero_hz"]
    wait_for_ticks(h, 4000)
    h.set("blocks.pi.kp", "6e7")  # the grammar of `set` lines: a text value, a `blocks.` path
    r = h.wait()
    (u,) = h.status()["updates"]
    assert (u["path"], u["value"]) == ("pi.kp", 6e7)
    j = math.ceil(u["tick"] / 10)  # the PI's sample computed at base tick 10·j
    assert 400 <= j < 1200
    before, after = r.signals["pi.u"], offline.signals["pi.u"]
    # u = (k_p + g·k_p)·e + x_i, g ≥ 0 the discretisation's direct share of
    # k_i = k_p·2π f_i, x_i the integrator the update keeps. While the error
    # is exactly 0 (the encoder's 5 nm reading on the 2.5 nm-per-sample
    # reference) the new k_p changes neither u nor x_i, so the runs part at
    # the first sample k ≥ j with an error, by at least Δk_p·|e| on its side.
    err = offline.signals["err.y"]
    k = j + int(np.argmax(err[j:] != 0.0))
    assert err[k] != 0.0
    assert np.array_equal(before[:k], after[:k])
    e = err[k]
    assert (before[k] - after[k]) * np.sign(e) >= (6e7 - 3.1416e7) * abs(e)


# A sine of 50 Hz (its phase keeps it off zero at every tick) through a 2nd-order Butterworth low-pass, at 1 kHz.
LOW_PASS = """
base_rate_hz: 1000
duration_s: 3.0
blocks:
  - { name: sine, type: sinusoid, amplitude: 1.0, frequency_hz: 50.0, phase_rad: 0.3 }
  - { name: lp, type: low_pass, order: 2, cutoff_hz: 200.0 }
connections:
  - { from: sine.y, to: lp.u }
log: [sine.y, lp.y]
"""


def butterworth_gain(f_hz: float, cutoff_hz: float, order: int, rate_hz: float) -> float:
    """|H(e^{jωT})| of the digital Butterworth low-pass (bilinear transform,
    cutoff pre-warped): 1/√(1 + (tan(π f T)/tan(π f_c T))^{2n})."""
    ratio = math.tan(math.pi * f_hz / rate_hz) / math.tan(math.pi * cutoff_hz / rate_hz)
    return 1.0 / math.sqrt(1.0 + ratio ** (2 * order))


def sine_fit(y: np.ndarray, f_hz: float, rate_hz: float, start: int, periods: int):
    """(a, b) of y[k] = a·sin(ωk) + b·cos(ωk), ω = 2π f/rate, fitted over
    `periods` whole periods from sample `start` by least squares (exact for
    a steady sine: sin and cos are orthogonal over whole periods)."""
    n = round(periods * rate_hz / f_hz)
    k = np.arange(start, start + n)
    w = 2.0 * math.pi * f_hz / rate_hz
    basis = np.column_stack([np.sin(w * k), np.cos(w * k)])
    (a, b), *_ = np.linalg.lstsq(basis, y[start : start + n], rcond=None)
    return a, b


def butterworth_b0(cutoff_hz: float, rate_hz: float) -> float:
    """b₀ of the 2nd-order digital Butterworth section: K²/(1 + √2·K + K²),
    K = tan(π f_c T)."""
    k = math.tan(math.pi * cutoff_hz / rate_hz)
    return k * k / (1.0 + math.sqrt(2.0) * k + k * k)


def test_a_low_pass_corner_set_while_the_loop_runs_attenuates_as_the_butterworth_closed_form():
    # 50 Hz through the 200 Hz corner passes at 0.99887…; with the corner
    # moved to 20 Hz mid-run it comes out at 0.15586… — each the digital
    # Butterworth's gain at 50 Hz, measured on the output of the running loop.
    f, rate = 50.0, 1000.0
    g = nm.Graph(yaml=LOW_PASS, origin="low_pass.yaml")
    h = g.rt_start(allow_soft=True, overrun="catch-up")
    assert h.live_params == ["lp.cutoff_hz"]
    wait_for_ticks(h, 800)
    h.set("lp.cutoff_hz", 20.0)
    r = h.wait()
    (u,) = h.status()["updates"]
    assert (u["path"], u["value"]) == ("lp.cutoff_hz", 20.0)
    tick = u["tick"]
    assert 800 <= tick <= 2000, tick
    assert r.timing["stop"] == "completed" and r.timing["param_updates"] == 1
    x, y = r.signals["sine.y"], r.signals["lp.y"]
    assert x.shape == y.shape == (3000,)
    assert abs(math.hypot(*sine_fit(x, f, rate, 0, 10)) - 1.0) < 1e-12
    # Before: the last 20 periods (400 ticks) before the update, the 200 Hz
    # filter's start-up long decayed (its poles' modulus 0.57 per tick).
    a, b = sine_fit(y, f, rate, tick - 400, 20)
    # After: 20 periods from 300 ticks past the update (the 20 Hz poles,
    # modulus 0.915 per tick, leave 0.915^300 ≈ 3e-12 of the switch).
    after = math.hypot(*sine_fit(y, f, rate, tick + 300, 20))
    expected = (butterworth_gain(f, 200.0, 2, rate), butterworth_gain(f, 20.0, 2, rate))
    assert abs(math.hypot(a, b) - expected[0]) < 1e-9 * expected[0], (a, b, expected)
    assert abs(after - expected[1]) < 1e-9 * expected[1], (after, expected)
    assert 0.98 < expected[0] and expected[1] < 0.16
    # The corner took effect at the tick reported, keeping the delay line:
    # y = z₀ + b₀·u, so there the output leaves the 200 Hz filter's steady
    # sine by exactly (b₀' − b₀)·u[tick] (docs/realtime.md, "A filter's corner").
    w = 2.0 * math.pi * f / rate
    old_filter = a * math.sin(w * tick) + b * math.cos(w * tick)
    step = (butterworth_b0(20.0, rate) - butterworth_b0(200.0, rate)) * x[tick]
    assert abs(y[tick] - old_filter - step) < 1e-9, (y[tick], old_filter, step)
    assert abs(step) > 1e-3


def test_updates_the_library_refuses_raise_naming_the_parameter_and_the_fix(root):
    g = quickstart(root)
    with g.rt_start(duration=20.0, allow_soft=True) as h:
        # The stability gate: k_p ten times the design's makes loop `pi` unstable.
        with pytest.raises(nm.GateError, match=r"`pi.kp` = 314160000 refused by the stability gate: loop `pi` is unstable: closed-loop pole of modulus 1.109953 ≥ 1"):
            h.set("pi.kp", 3.1416e8)
        with pytest.raises(nm.GraphError, match=r"`kq` of block `pi` cannot change while the loop runs \(its live parameters: kp, zero_hz\) \(fix: set it before the run with `--set blocks.pi.kq=VALUE`"):
            h.set("pi.kq", 1.0)
        with pytest.raises(nm.GraphError, match=r"the graph has no block `nope`.*live parameters of this graph: pi.kp, pi.zero_hz"):
            h.set("nope.kp", 1.0)
        with pytest.raises(nm.GraphError, match=r'`pi.kp`: `"abc"` is not a finite number \(fix: give a number'):
            h.set("pi.kp", "abc")
        with pytest.raises(nm.GraphError, match=r"`pi.kp`: `true` is not a finite number"):
            h.set("pi.kp", True)
        with pytest.raises(nm.GraphError, match=r"`pi.kp`: `inf` is not a finite number"):
            h.set("pi.kp", float("inf"))
        # The block's own validation: a negative corner.
        with pytest.raises(nm.GraphError, match=r"`pi.zero_hz` = -1 refused by block `pi` \(pi\)"):
            h.set("pi.zero_hz", -1.0)
        t0 = time.monotonic()
        r = h.stop()
        stopped_in = time.monotonic() - t0
    # Nothing reached the loop; stopped at a tick boundary long before its 20 s.
    assert r.timing["param_updates"] == 0
    assert r.timing["stop"] == "interrupted"
    assert 0 < r.timing["ticks"] < 20.0 * g.base_rate_hz
    assert r.signals["pi.u"].shape[0] == math.ceil(r.timing["ticks"] / 10)
    assert stopped_in < 5.0
    assert h.result is r


def test_the_context_manager_waits_and_stops_when_its_block_raises():
    with nm.rt_start(gain_graph(duration=0.2), allow_soft=True, overrun="catch-up") as h:
        h.set("k.k", 5.0)
    r = h.result
    assert r.timing["stop"] == "completed" and r.timing["ticks"] == 200
    (u,) = h.status()["updates"]
    assert np.all(r.signals["k.y"][u["tick"]:] == 5.0)
    assert np.all(r.signals["k.y"][: u["tick"]] == 2.0)

    t0 = time.monotonic()
    with pytest.raises(ZeroDivisionError):
        with nm.rt_start(gain_graph(duration=30.0), allow_soft=True) as h:
            wait_for_ticks(h, 100)
            1 / 0
    assert time.monotonic() - t0 < 10.0
    assert h.result.timing["stop"] == "interrupted"
    assert 100 <= h.result.timing["ticks"] < 30000


def loop_threads() -> int:
    """Threads of this process named like the loop thread."""
    n = 0
    for task in os.listdir("/proc/self/task"):
        try:
            with open(f"/proc/self/task/{task}/comm") as f:
                n += f.read().strip() == "nanomotion-rt"
        except FileNotFoundError:
            pass  # the thread ended meanwhile
    return n


def test_ctrl_c_while_waiting_and_a_dropped_handle_stop_the_loop():
    assert loop_threads() == 0
    h = nm.rt_start(gain_graph(duration=30.0), allow_soft=True)
    wait_for_ticks(h, 100)
    assert loop_threads() == 1
    # Ctrl-C (SIGINT, as the terminal sends it) while waiting: the loop stops
    # at a tick boundary, the KeyboardInterrupt goes on, the run is kept.
    threading.Timer(0.2, _thread.interrupt_main).start()
    t0 = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        h.wait()
    assert time.monotonic() - t0 < 10.0
    assert loop_threads() == 0
    assert not h.running and not h.status()["running"]
    r = h.wait()
    assert r.timing["stop"] == "interrupted" and 100 <= r.timing["ticks"] < 30000
    assert np.all(r.signals["k.y"] == 2.0)

    # A handle dropped while its loop runs stops the loop and waits for it.
    h = nm.rt_start(gain_graph(duration=30.0), allow_soft=True)
    wait_for_ticks(h, 100)
    assert loop_threads() == 1
    t0 = time.monotonic()
    del h
    gc.collect()
    assert time.monotonic() - t0 < 10.0
    assert loop_threads() == 0


@pytest.fixture
def plant(root, cli):
    """`nanomotion plant` serving the quickstart's stage under a fresh name."""
    name = f"pytest-{os.getpid()}-{time.monotonic_ns() % 10**9}"
    p = subprocess.Popen(
        [*cli, "plant", str(root / "examples/realtime/quickstart_plant.yaml"), "--serve", name,
         "--allow-soft", "--overrun", "catch-up", "--watchdog-ms", "2000"],
        cwd=root, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    yield name, p
    if p.poll() is None:
        p.kill()
    p.wait(timeout=30)


def test_a_controller_drives_a_plant_in_another_process_and_takes_a_live_gain(root, plant):
    name, proc = plant
    controller = root / "examples/realtime/quickstart_controller.yaml"
    h = nm.rt_start(controller, duration=1.0, allow_soft=True, overrun="catch-up",
                    device=f"shm:{name}", connect_timeout=60.0, watchdog_ms=2000.0)
    assert h.device == f"shm:{name}"
    wait_for_ticks(h, 2000)
    # The loop closes through the device: the gate judges an update on it,
    # joined with the served plant and the device's one tick, where ten times
    # the design's k_p is unstable (the graph alone has no loop to judge).
    with pytest.raises(nm.GateError, match=rf"`pi.kp` = 314160000 refused by the stability gate on the loop through device `shm:{name}` with its latency of 1 tick: loop `pi` is unstable: closed-loop pole of modulus 1.068204 ≥ 1; with the values accepted so far loop `pi` had phase margin 76.16°"):
        h.set("pi.kp", 3.1416e8)
    h.set("pi.kp", 4e7)
    r = h.wait()
    out, _ = proc.communicate(timeout=60)
    assert proc.returncode == 0, out
    assert "the controller closed the connection" in out
    t = r.timing
    assert (t["stop"], t["ticks"], t["device_latency_ticks"]) == ("completed", 4000, 1)
    # The stability gate judged the loop through the device, with the plant's
    # graph and the device's latency of one tick (T = 250 µs): the
    # quickstart's phase margin less 360°·f_c·T.
    (line,) = r.stability_gate
    assert line.startswith(f"loop `pi` closed through device `shm:{name}` with its latency of 1 tick (250.0 µs): phase margin 76.")
    (u,) = h.status()["updates"]
    j = u["tick"]
    assert 2000 <= j < 4000
    assert r.signals["pi.u"].shape == (4000,)
    # The loop was closed through the other process: the stage followed the
    # 10 µm/s ramp to 10 µm. A plant scheduled late delays the position it
    # publishes; 2 % of the ramp is 20 ms of lateness, far beyond a loaded
    # machine's stalls (docs/realtime.md).
    ref, pos = r.signals["ref.y"], r.signals["position.y"]
    assert ref[-1] == pytest.approx(1e-5 * 3999 / 4000, rel=1e-12)
    assert abs(pos[-1] - ref[-1]) < 0.02 * ref[-1], (pos[-1], ref[-1])
    # And tracking without a steady error (type-2 loop), within a few
    # encoder steps (5 nm), before and after the gain change.
    err = ref - pos
    assert abs(np.mean(err[1000:j])) < 4 * 5e-9
    assert abs(np.mean(err[j + 400:])) < 4 * 5e-9


def test_a_loop_whose_margin_the_devices_latency_eats_is_refused_before_it_runs(root, cli, tmp_path):
    # The quickstart's delay margin is 10.617 ms, 42.47 controller ticks
    # (`nanomotion check examples/quickstart.yaml`; nanomotion-rt's
    # tests/through.rs computes it and refuses 43 ticks of latency, passes 42).
    # A plant that itself delays the drive by 42 ticks leaves less than the
    # shared-memory device's one tick of latency: the joined loop is refused.
    text = (root / "examples/realtime/quickstart_plant.yaml").read_text()
    text = text.replace("  - { from: drive.y, to: stage.u }",
                        "  - { from: drive.y, to: late.u }\n  - { from: late.y, to: stage.u }")
    text = text.replace("  - name: stage ", "  - { name: late, type: delay, d: 42, rate_hz: 4000 }\n  - name: stage ")
    assert "late.y" in text and "type: delay" in text
    plant_yaml = tmp_path / "late_plant.yaml"
    plant_yaml.write_text(text)
    name = f"pytest-late-{os.getpid()}"
    p = subprocess.Popen([*cli, "plant", str(plant_yaml), "--serve", name, "--allow-soft"],
                         cwd=root, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        with pytest.raises(nm.GateError, match=(
                rf"the loop through device `shm:{name}` with its latency of 1 tick: the stability gate "
                r"refuses the graph \(see nanomotion.check; fix the loop, or run anyway with "
                r"allow_unproven=True\):\n  loop `pi` is unstable: closed-loop pole of modulus 1.0")):
            nm.rt_start(root / "examples/realtime/quickstart_controller.yaml", allow_soft=True,
                        device=f"shm:{name}", connect_timeout=60.0)
        # Refused before the loop: the device was let go, the plant stops.
        out, _ = p.communicate(timeout=60)
        assert p.returncode == 0, out
        assert "the controller closed the connection" in out
    finally:
        if p.poll() is None:
            p.kill()
            p.wait(timeout=30)


def test_a_bad_device_raises_naming_the_setting_and_the_fix(root):
    controller = root / "examples/realtime/quickstart_controller.yaml"
    with pytest.raises(nm.GraphError, match=r"device `tcp:stage`: unknown device \(fix: `shm:NAME` for a plant served by `nanomotion plant GRAPH --serve NAME`\)"):
        nm.rt(controller, allow_soft=True, device="tcp:stage")
    with pytest.raises(nm.GraphError, match=r"no plant serves `nobody-serves-this`.*fix: start `nanomotion plant PLANT.yaml --serve nobody-serves-this` first"):
        nm.rt(controller, allow_soft=True, device="shm:nobody-serves-this", connect_timeout=0.0)
    with pytest.raises(nm.GraphError, match=r"connect_timeout: connect timeout NaN s: must be a finite number ≥ 0"):
        nm.rt(controller, allow_soft=True, device="shm:x", connect_timeout=float("nan"))
    with pytest.raises(nm.GraphError, match=r"watchdog_ms: watchdog -1 ms: must be in \(0, 60000\] ms \(fix: e.g. 50 ms\)"):
        nm.rt(controller, allow_soft=True, device="shm:x", watchdog_ms=-1.0)
    # hw blocks without a device: the runner's wiring error, with its fix.
    with pytest.raises(nm.GraphError, match=r"block `position` \(hw_input\): no device input channel of that name on device `none`"):
        nm.rt(controller, allow_soft=True)

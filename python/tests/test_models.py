"""Hysteresis, its inverse and the time-stamping estimator against independent
computations."""

import json

import numpy as np
import pytest

import nanomotion as nm


def rk4_ch(u: np.ndarray, alpha: float, b: float, c: float, substeps: int = 200) -> np.ndarray:
    """dy/du = alpha·sign(du)(b u − y) + c along piecewise-linear u, by RK4."""
    y, out = 0.0, []
    for k in range(len(u)):
        u0 = 0.0 if k == 0 else u[k - 1]
        du = (u[k] - u0) / substeps
        sgn = np.sign(du)
        f = lambda uu, yy: alpha * sgn * (b * uu - yy) + c  # noqa: E731
        uu = u0
        for _ in range(substeps):
            k1 = f(uu, y)
            k2 = f(uu + du / 2, y + du / 2 * k1)
            k3 = f(uu + du / 2, y + du / 2 * k2)
            k4 = f(uu + du, y + du * k3)
            y += du / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            uu += du
        out.append(y)
    return np.array(out)


def test_coleman_hodgdon_matches_an_ode_integration():
    alpha, b, c = 0.03, 1.0, 0.7
    u = np.concatenate([np.linspace(0, 100, 41), np.linspace(97.5, 20, 32), np.linspace(25, 80, 12)])
    y = nm.ColemanHodgdon(alpha, b, c).simulate(u)
    np.testing.assert_allclose(y, rk4_ch(u, alpha, b, c), rtol=1e-9, atol=1e-9)


def test_periodic_orbit_is_the_closed_form_loop():
    alpha, b, c = 0.03, 1.0, 0.7
    h = nm.ColemanHodgdon(alpha, b, c)
    up, down = np.linspace(0, 100, 101), np.linspace(100, 0, 101)
    u = np.concatenate([np.concatenate([up, down]) for _ in range(8)])
    y = h.simulate(u)
    # (6.3) written out independently.
    k, er = (b - c) / alpha, np.exp(-alpha * 100.0)
    trace = b * up - k * (1 - 2 * np.exp(-alpha * up) / (1 + er))
    retrace = b * down + k * (1 - 2 * np.exp(alpha * (down - 100)) / (1 + er))
    np.testing.assert_allclose(y[-202:-101], trace, atol=1e-8)
    np.testing.assert_allclose(y[-101:], retrace, atol=1e-8)
    np.testing.assert_allclose(h.steady_loop(up, 0.0, 100.0, "trace"), trace, atol=1e-10)


def test_inverse_feedforward_inverts_the_branch():
    h = nm.ColemanHodgdon(0.03, 1.0, 0.7)
    inv = nm.HysteresisInverse(20.0, 60.0, model=h)
    for direction in ("trace", "retrace"):
        v_lo, v_hi = inv.voltage_range(direction)
        for x in np.linspace(20.0, 60.0, 17):
            v = inv.voltage(x, direction)
            assert v_lo - 1e-9 <= v <= v_hi + 1e-9
            # forward map (6.3) on [v_lo, v_hi], independently of the library
            alpha, b, c = 0.03, 1.0, 0.7
            k, er = (b - c) / alpha, np.exp(-alpha * (v_hi - v_lo))
            if direction == "trace":
                xv = b * v - k * (1 - 2 * np.exp(-alpha * (v - v_lo)) / (1 + er))
            else:
                xv = b * v + k * (1 - 2 * np.exp(alpha * (v - v_hi)) / (1 + er))
            assert xv == pytest.approx(x, abs=1e-9)
    with pytest.raises(nm.ModelError, match="outside"):
        inv.voltage(75.0, "trace")


def test_inverse_sequence_follows_the_reference_direction():
    h = nm.ColemanHodgdon(0.03, 1.0, 0.7)
    inv = nm.HysteresisInverse(20.0, 60.0, model=h)
    x = np.concatenate([np.linspace(20, 60, 50), np.linspace(59, 20, 49)])
    v = inv.run(x)
    assert inv.out_of_range == 0
    # Up on the trace branch, down on the retrace branch: each maps back to x.
    back = [inv.position(vv, "trace" if i < 50 else "retrace") for i, vv in enumerate(v)]
    np.testing.assert_allclose(back, x, atol=1e-9)


def test_extended_model_parameters_and_errors():
    ext = {"trace": {"a_um_per_v": 0.0, "b_um_per_v": 1.0, "c_per_v": 0.0, "u_um_per_v": 0.7,
                     "alpha_per_v": 0.03, "d_um_per_v2": 0.0, "e_um_per_v": 0.0, "f_um": 0.0}}
    ext["retrace"] = dict(ext["trace"])
    inv = nm.HysteresisInverse(20.0, 60.0, extended_json=json.dumps(ext))
    ref = nm.HysteresisInverse(20.0, 60.0, model=nm.ColemanHodgdon(0.03, 1.0, 0.7))
    assert inv.voltage(33.0, "trace") == pytest.approx(ref.voltage(33.0, "trace"), abs=1e-12)
    ext["trace"]["alpha_per_v"] = -1.0
    with pytest.raises(nm.ModelError, match="alpha_per_v"):
        nm.HysteresisInverse(20.0, 60.0, extended_json=json.dumps(ext))
    with pytest.raises(nm.ModelError, match="alpha"):
        nm.ColemanHodgdon(0.0, 1.0, 0.7)


def quadratic_register(t_c, x0, v, a, n, lo):
    """Register [c, n_valid, t_1, x_1, ...] (newest first) of x(t) = x0 + v t + a t²/2
    crossing the integer levels lo, lo+1, ... (a > 0, v > 0: increasing)."""
    events = []
    level = lo
    while True:
        # solve a/2 t² + v t + (x0 - level) = 0 for the positive root
        tt = (-v + np.sqrt(v * v - 2 * a * (x0 - level))) / a
        if tt > t_c:
            break
        events.append((tt, float(level)))
        level += 1
    events = events[-n:][::-1]
    x_c = x0 + v * t_c + a * t_c**2 / 2
    reg = [np.floor(x_c), float(len(events))]
    for tt, lv in events:
        reg += [tt, lv]
    reg += [0.0] * (2 + 2 * n - len(reg))
    return np.array(reg)


def test_time_stamping_fit_is_exact_on_a_quadratic_motion():
    res = 2 * np.pi / 400
    est = nm.TimestampEstimator(res, order=2, register_len=5)
    x0, v, a = 0.3, 40.0, 900.0  # counts, counts/s, counts/s²
    t = np.array([0.05, 0.08, 0.1])
    regs = np.stack([quadratic_register(tc, x0, v, a, 5, 1) for tc in t])
    y, status = est.estimate(t, regs)
    assert list(status) == [0, 0, 0]
    np.testing.assert_allclose(y[:, 0], res * (x0 + v * t + a * t**2 / 2), rtol=1e-9)
    np.testing.assert_allclose(y[:, 1], res * (v + a * t), rtol=1e-7)
    np.testing.assert_allclose(y[:, 2], res * a, rtol=1e-5)


def test_time_stamping_beats_the_count_on_a_sinusoid():
    # 100-line encoder, 1 kHz reads, (pi/2) sin(2 pi t) rad: the estimate is far
    # closer to the true position than the count, and its velocity error far
    # below that of differencing the count.
    fs = 1000.0
    t = np.arange(0, 2.0, 1 / fs)
    amp, w = np.pi / 2, 2 * np.pi
    x, v = amp * np.sin(w * t), amp * w * np.cos(w * t)
    est, status, count, regs = nm.timestamp_track(t, x, v, encoder={"lines": 100})
    assert regs.shape == (t.size, 12)
    k = t > 0.2
    pos_err = np.sqrt(np.mean((est[k, 0] - x[k]) ** 2))
    count_err = np.sqrt(np.mean((count[k] - x[k]) ** 2))
    assert pos_err < 0.2 * count_err
    vel_diff = np.diff(count) * fs
    diff_err = np.sqrt(np.mean((vel_diff[k[1:]] - v[1:][k[1:]]) ** 2))
    vel_err = np.sqrt(np.mean((est[k, 1] - v[k]) ** 2))
    assert vel_err < 0.1 * diff_err
    with pytest.raises(nm.ModelError, match="register_len"):
        nm.TimestampEstimator(res := 0.01, order=3, register_len=3)
    assert res == 0.01

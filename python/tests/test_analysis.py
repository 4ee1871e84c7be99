"""Analysis helpers against closed forms and independent numpy computations."""

import numpy as np
import pytest

import nanomotion as nm


def second_order(wn: float, zeta: float):
    return nm.Lti.tf([wn**2], [1.0, 2 * zeta * wn, wn**2])


def test_frf_of_second_order_system_matches_closed_form():
    wn, zeta = 2 * np.pi * 575.0, 0.05
    w = np.logspace(1, 5, 400)
    h = second_order(wn, zeta).freqresp(w)
    s = 1j * w
    want = wn**2 / (s**2 + 2 * zeta * wn * s + wn**2)
    assert h.shape == (400,)
    np.testing.assert_allclose(h, want, rtol=1e-9)
    # Resonance: |H(j wn)| = 1 / (2 zeta), phase -90°.
    hr = second_order(wn, zeta).freqresp(np.array([wn]))[0]
    assert abs(abs(hr) - 1 / (2 * zeta)) < 1e-8
    assert abs(np.angle(hr, deg=True) + 90.0) < 1e-8


def test_discrete_frf_uses_z_on_the_unit_circle():
    dt = 1e-3
    g = nm.Lti.tf([0.5], [1.0, -0.5], dt=dt)  # 0.5 / (z - 0.5)
    w = np.linspace(0.0, np.pi / dt, 50)
    z = np.exp(1j * w * dt)
    np.testing.assert_allclose(g.freqresp(w), 0.5 / (z - 0.5), rtol=1e-12)


def test_hinf_norm_matches_brute_force_grid_and_closed_form():
    wn, zeta = 100.0, 0.1
    g = second_order(wn, zeta)
    norm, peak = g.hinfnorm()
    # Closed form for zeta < 1/sqrt(2): peak 1/(2 zeta sqrt(1 - zeta²)) at wn sqrt(1 - 2 zeta²).
    assert norm == pytest.approx(1 / (2 * zeta * np.sqrt(1 - zeta**2)), rel=1e-8)
    assert peak == pytest.approx(wn * np.sqrt(1 - 2 * zeta**2), rel=1e-5)
    # Brute force: a dense grid of the closed-form response.
    w = np.linspace(1.0, 300.0, 2_000_001)
    s = 1j * w
    brute = np.max(np.abs(wn**2 / (s**2 + 2 * zeta * wn * s + wn**2)))
    assert brute <= norm * (1 + 1e-12)
    assert norm == pytest.approx(brute, rel=1e-8)


def test_hinf_norm_of_mimo_state_space_against_grid():
    # Two decoupled lightly damped modes plus coupling through C: sigma_max on a grid.
    a = np.array([[0, 1, 0, 0], [-400, -4, 0, 0], [0, 0, 0, 1], [0, 0, -2500, -10.0]])
    b = np.array([[0, 0], [1, 0], [0, 0], [0, 1.0]])
    c = np.array([[1, 0, 0.5, 0], [0, 0.2, 1, 0.0]])
    d = np.zeros((2, 2))
    g = nm.Lti.ss(a, b, c, d)
    norm, _ = g.hinfnorm()
    w = np.linspace(0.1, 200.0, 200_001)
    resp = g.freqresp(w)
    assert resp.shape == (w.size, 2, 2)
    # independent evaluation of C (jwI - A)^-1 B at the grid's best point region
    sig = np.linalg.svd(resp, compute_uv=False)[:, 0]
    k = int(np.argmax(sig))
    direct = c @ np.linalg.solve(1j * w[k] * np.eye(4) - a, b) + d
    np.testing.assert_allclose(resp[k], direct, rtol=1e-10)
    assert norm == pytest.approx(sig.max(), rel=1e-6)


def test_unstable_hinf_norm_raises_with_the_library_message():
    g = nm.Lti.tf([1.0], [1.0, -1.0])
    with pytest.raises(nm.AnalysisError, match="system is not stable: the H∞ norm of an unstable system is infinite"):
        g.hinfnorm()
    assert issubclass(nm.AnalysisError, nm.NanomotionError)


def test_margins_of_a_third_order_loop():
    # L(s) = 2/(s+1)^3: phase -180° at w = sqrt(3) where |L| = 2/8: GM = 4.
    m = nm.Lti.tf([2.0], [1.0, 3.0, 3.0, 1.0]).margins()
    assert m["gain_margin"] == pytest.approx(4.0, rel=1e-8)
    assert m["phase_crossover_rad_s"] == pytest.approx(np.sqrt(3.0), rel=1e-8)
    # Gain crossover: |L| = 1 at (1 + w²)^{3/2} = 2; the phase margin from it.
    wc = np.sqrt(2 ** (2 / 3) - 1)
    assert m["gain_crossover_rad_s"] == pytest.approx(wc, rel=1e-6)
    assert m["phase_margin_deg"] == pytest.approx(180 - 3 * np.degrees(np.arctan(wc)), rel=1e-6)
    # Modulus margin: min |1 + L| on a dense grid.
    w = np.linspace(0.0, 20.0, 400_001)
    mm = np.min(np.abs(1 + 2 / (1j * w + 1) ** 3))
    assert m["modulus_margin"] == pytest.approx(mm, rel=1e-6)


def test_improper_transfer_function_is_refused():
    with pytest.raises(nm.AnalysisError, match="improper transfer function: numerator degree 2 > denominator degree 1"):
        nm.Lti.tf([1.0, 0.0, 0.0], [1.0, 1.0])


def test_welch_psd_parseval_and_sine_power():
    fs, n = 1000.0, 4096
    rng = np.random.default_rng(3)
    x = rng.normal(size=n) + 0.3
    # Rectangular window, one segment, mean removal: sum S df is exactly the variance.
    f, s = nm.psd_welch(x, fs, segment_len=n, window="rectangular")
    assert f[1] - f[0] == pytest.approx(fs / n)
    assert np.sum(s) * (f[1] - f[0]) == pytest.approx(np.var(x), rel=1e-10)
    # A sine of amplitude A on a bin: its power A²/2 sits in that bin.
    a, k = 2e-6, 256
    t = np.arange(n) / fs
    f, s = nm.psd_welch(a * np.sin(2 * np.pi * k * fs / n * t), fs, segment_len=n, window="rectangular")
    assert s[k] * (f[1] - f[0]) == pytest.approx(a**2 / 2, rel=1e-9)
    # Against a direct periodogram with Hann segments and 50 % overlap (numpy only).
    seg = 512
    f, s = nm.psd_welch(x, fs, segment_len=seg)
    w = 0.5 - 0.5 * np.cos(2 * np.pi * np.arange(seg) / seg)
    acc = np.zeros(seg // 2 + 1)
    starts = range(0, n - seg + 1, seg // 2)
    for i in starts:
        y = x[i:i + seg] - np.mean(x[i:i + seg])
        acc += np.abs(np.fft.rfft(y * w)) ** 2 / (fs * np.sum(w**2))
    acc /= len(starts)
    acc[1:-1] *= 2
    np.testing.assert_allclose(s, acc, rtol=1e-10)


def test_cumulative_psd_ends_at_the_variance():
    fs, n = 4000.0, 8192
    x = np.random.default_rng(7).normal(scale=3e-9, size=n)
    f, c = nm.cumulative_psd(x, fs, segment_len=n, window="rectangular")
    assert np.all(np.diff(c) >= 0)
    assert c[-1] == pytest.approx(np.var(x), rel=1e-10)
    f2, c2 = nm.cumulative_psd(x, fs)  # the CLI plot's segmentation (Hann)
    assert f2[-1] == pytest.approx(fs / 2)
    assert c2[-1] == pytest.approx(np.var(x), rel=0.05)


def test_frf_h1_of_a_delay_and_gain():
    fs = 1000.0
    u = np.random.default_rng(5).normal(size=40_000)
    y = np.concatenate([[0.0], 0.5 * u[:-1]])
    f, h, coh = nm.frf_h1(u, y, fs, segment_len=256)
    band = (f > 5) & (f < 450)
    np.testing.assert_allclose(np.abs(h[band]), 0.5, rtol=0.01)
    np.testing.assert_allclose(np.angle(h[band] * np.exp(2j * np.pi * f[band] / fs)), 0.0, atol=0.02)
    assert np.all(coh[band] > 0.98)


def test_bad_analysis_arguments_raise_typed_errors():
    with pytest.raises(nm.AnalysisError, match="signal lengths differ: 10 vs 9 samples"):
        nm.frf_h1(np.zeros(10), np.zeros(9), 1.0)
    with pytest.raises(nm.AnalysisError, match="window"):
        nm.psd_welch(np.zeros(64), 1.0, segment_len=16, window="blackman")

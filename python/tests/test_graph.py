"""Graphs from Python against the CLI and against predictions."""

import json
import re

import numpy as np
import pytest

import nanomotion as nm
from conftest import run_cli


def test_run_scores_equal_the_cli_metrics_json(root, cli, tmp_path):
    out = tmp_path / "qs"
    p = run_cli(cli, "run", "examples/quickstart.yaml", "--out", str(out))
    assert p.returncode == 0, p.stderr
    metrics = json.loads((out / "metrics.json").read_text())
    r = nm.run(root / "examples/quickstart.yaml")
    assert r.duration_s == metrics["duration_s"]
    assert {s["signal"] for s in metrics["scores"]} == set(r.scores)
    for s in metrics["scores"]:
        mine = r.scores[s["signal"]]
        assert mine.rms == pytest.approx(s["rms"], rel=1e-12)
        assert mine.max_abs == pytest.approx(s["max_abs"], rel=1e-12)
        assert mine.mean == pytest.approx(s["mean"], rel=1e-9, abs=1e-18)
        assert mine.samples == s["samples"]
    # The scored signals are logged too: the rms recomputed in numpy, and the
    # cumulative PSD's end value against the CLI's.
    for s in metrics["scores"]:
        x = r.signals[s["signal"]]
        first = int(round(s["from_s"] * r.rates_hz[s["signal"]]))
        assert np.sqrt(np.mean(x[first:] ** 2)) == pytest.approx(s["rms"], rel=1e-9)
    for c in metrics["cumulative_psd_end"]:
        x = r.signals[c["signal"]]
        first = int(round(c["from_s"] * r.rates_hz[c["signal"]]))
        _, cp = nm.cumulative_psd(np.ascontiguousarray(x[first:]), r.rates_hz[c["signal"]])
        assert cp[-1] == pytest.approx(c["end"], rel=1e-9)


def test_signals_are_numpy_arrays_at_their_rates(root):
    r = nm.run(root / "examples/quickstart.yaml", duration=0.75)
    y = r.signals["stage.y"]
    assert isinstance(y, np.ndarray) and y.dtype == np.float64
    assert r.rates_hz["stage.y"] == 40000.0 and r.rates_hz["pi.u"] == 4000.0
    assert y.shape == (30000,) and r.signals["pi.u"].shape == (3000,)
    assert r.units["stage.y"] == "m"
    # The reference is a ramp at 10 µm/s: ref.y(t) = 1e-5 t.
    np.testing.assert_allclose(r.signals["ref.y"], 1e-5 * r.time("ref.y"), rtol=1e-12, atol=1e-18)
    assert r.time("stage.y")[1] == pytest.approx(1 / 40000)


def test_seed_and_duration_overrides(root):
    g = nm.load(root / "examples/quickstart.yaml")
    assert g.duration_s == 2.0 and g.seed == 1 and ("pi", "pi") in g.blocks
    a = g.run(duration=0.6)
    b = g.run(duration=0.6)
    np.testing.assert_array_equal(a.signals["stage.y"], b.signals["stage.y"])  # deterministic
    assert a.duration_s == pytest.approx(0.6)
    assert a.scores["err.y"].samples == int(round((0.6 - 0.5) * 4000))


GAIN_GRAPH = """\
base_rate_hz: 1000
duration_s: 0.01
blocks:
  - {{ name: c, type: constant, value: 2.0 }}
  - {{ name: k, type: gain, k: {gain} }}
connections:
  - {{ from: c.y, to: k.u }}
log: [k.y]
score:
  - {{ signal: k.y }}
"""


def test_graph_from_text_and_a_parameter_change_changes_the_result_as_predicted():
    r1 = nm.run(nm.Graph(yaml=GAIN_GRAPH.format(gain=3.0)))
    r2 = nm.run(nm.Graph(yaml=GAIN_GRAPH.format(gain=-0.5)))
    np.testing.assert_array_equal(r1.signals["k.y"], np.full(10, 6.0))
    assert r1.scores["k.y"].rms == pytest.approx(6.0)
    assert r2.scores["k.y"].mean == pytest.approx(-1.0)


def test_bad_yaml_raises_with_the_line_and_the_cli_message(cli, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("base_rate_hz: 1000\nduration_s: 1\nblocks:\n  - { name: c, type: constnt, value: 1 }\n")
    with pytest.raises(nm.GraphError) as e:
        nm.load(bad)
    msg = str(e.value)
    assert re.search(r"line 4", msg), msg
    assert "constant" in msg  # the suggestion for the misspelt type
    p = run_cli(cli, "check", str(bad))
    assert p.returncode == 1
    assert p.stderr.strip() == f"error: {msg}"
    # A syntax error.
    bad.write_text("base_rate_hz: 1000\nduration_s: [1\nblocks: []\n")
    with pytest.raises(nm.GraphError, match=r"line \d"):
        nm.run(bad)
    with pytest.raises(nm.NanomotionError):
        nm.Graph(yaml="base_rate_hz: -5\nduration_s: 1\nblocks: []\n").run()


def test_check_returns_the_gate_verdict_and_run_refuses_an_unstable_loop(root, tmp_path):
    ok = nm.check(root / "examples/quickstart.yaml")
    assert ok.passes and bool(ok)
    assert "pi" in " ".join(ok.order)
    assert "stability gate" in ok.report
    # The same loop with 1000× the gain: the gate must refuse it.
    text = (root / "examples/quickstart.yaml").read_text().replace("kp: 3.1416e7", "kp: 3.1416e10")
    g = nm.Graph(yaml=text, origin="hot.yaml")
    verdict = g.check()
    assert not verdict.passes and verdict.failures
    with pytest.raises(nm.GateError, match="the stability gate refuses the graph"):
        g.run(duration=0.6)
    # Run anyway: the gate's lines say so, and the loop diverges as predicted
    # (the error grows by orders of magnitude against the nominal loop).
    r = g.run(duration=0.6, allow_unproven=True)
    assert any("allow_unproven" in line for line in r.stability_gate)
    nominal = nm.run(root / "examples/quickstart.yaml", duration=0.6)
    assert r.scores["true_err.y"].max_abs > 100 * nominal.scores["true_err.y"].max_abs


def test_data_file_is_required_and_played(root):
    model = root / "examples/diagnose/model.yaml"
    with pytest.raises(nm.DataError, match="no data was given"):
        nm.run(model)
    r = nm.run(model, data=root / "examples/diagnose/record.csv")
    assert r.comparisons and all(c["samples"] > 0 for c in r.comparisons)
    with pytest.raises(nm.DataError):
        nm.run(model, data=root / "examples/quickstart.yaml")


def test_diagnose_names_the_hidden_hysteresis(root):
    d = nm.diagnose(root / "examples/diagnose/model.yaml", root / "examples/diagnose/record.csv",
                    max_effects=1, effects=["hysteresis", "time_delay"])
    assert d.found == ["hysteresis"]
    assert d.augmented_yaml and "hysteresis" in d.augmented_yaml
    assert d.report["final"]["holdout_rms"] < d.report["nominal"]["holdout_rms"]
    with pytest.raises(nm.DiagnoseError, match="holdout"):
        nm.diagnose(root / "examples/diagnose/model.yaml", root / "examples/diagnose/record.csv", holdout=0.95)
    # A declared phase the model lacks is refused, naming it and the fix.
    with pytest.raises(nm.DiagnoseError, match="phase.*no block `leg`"):
        nm.diagnose(root / "examples/diagnose/model.yaml", root / "examples/diagnose/record.csv",
                    phase="leg.y")


def test_diagnose_decides_on_a_record_it_did_not_fit(root, tmp_path):
    # The record's first 70 % estimates, its last 30 % — as a record of its own,
    # simulated from rest — decides.
    lines = (root / "examples/diagnose/record.csv").read_text().splitlines()
    head = [ln for ln in lines if ln.startswith("#")]
    header, rows = lines[len(head)], lines[len(head) + 1:]
    cut = int(0.7 * len(rows))
    est, val = tmp_path / "est.csv", tmp_path / "val.csv"
    est.write_text("\n".join(head + [header] + rows[:cut]) + "\n")
    val.write_text("\n".join(head + [header] + rows[cut:]) + "\n")
    d = nm.diagnose(root / "examples/diagnose/model.yaml", est, validation=[val],
                    max_effects=1, effects=["hysteresis", "time_delay"])
    assert d.found == ["hysteresis"]
    assert len(d.report["records"]) == 2
    assert d.report["estimation_samples"] == cut
    assert d.report["holdout_samples"] == len(rows) - cut


def test_dotted_path_overrides_change_the_result_as_predicted(root):
    g = nm.Graph(yaml=GAIN_GRAPH.format(gain=3.0))
    r = nm.run(g, {"blocks.k.k": 5.0, "blocks.c.value": -0.25, "duration_s": 0.005})
    np.testing.assert_array_equal(r.signals["k.y"], np.full(5, -1.25))
    # The quickstart stage integrates the drive frequency f_α with c = 4 µm per
    # cycle at low frequency (DC gain of (b s + k) c / (M s² + b s + k) is c):
    # tracking a ramp of velocity v needs a mean f_α = v / c, whatever the
    # controller. Doubling the reference velocity doubles it.
    c = 13.3135 / 3.32837e6
    for v in (1e-5, 2e-5):
        r = nm.run(root / "examples/quickstart.yaml", {"blocks.ref.velocity_m_s": v}, duration=1.0)
        u = r.signals["pi.u"][int(0.5 * r.rates_hz["pi.u"]):]
        assert np.mean(u) == pytest.approx(v / c, rel=0.02)
    # Overrides compose with Graph.with_overrides, later ones win.
    g2 = nm.load(root / "examples/quickstart.yaml").with_overrides({"seed": 7, "duration_s": 0.6})
    assert g2.seed == 7 and g2.duration_s == 0.6
    with pytest.raises(nm.GraphError, match="did you mean `blocks.pi.kp`"):
        nm.run(root / "examples/quickstart.yaml", {"blocks.pi.kpp": 1.0})


def test_compensate_inverts_the_named_hysteresis(root, tmp_path):
    d = nm.diagnose(root / "examples/compensate/model.yaml", root / "examples/compensate/record.csv",
                    max_effects=1, effects=["hysteresis"])
    assert d.found == ["hysteresis"]
    aug = tmp_path / "model_augmented.yaml"
    aug.write_text(d.augmented_yaml)
    (tmp_path / "report.json").write_text(json.dumps(d.report))
    c = nm.compensate(aug, root / "examples/compensate/controller.yaml")
    assert c.kept == ["comp_hysteresis"]
    assert "hysteresis_inverse" in c.compensated_yaml
    r = c.report
    assert r["cut_percent"] == pytest.approx(100 * (1 - r["after"]["rms"] / r["before"]["rms"]))
    assert r["cut_percent"] > 80
    with pytest.raises(nm.DiagnoseError, match="mux.in0"):
        nm.compensate(aug, root / "examples/quickstart.yaml")


def test_compensate_takes_a_measured_alpha_record_and_a_delay_margin(root, cli, tmp_path):
    # The position-ripple example: delay-varying RC on stage.y (pitch 0.5 µm,
    # 4 kHz). A record of the position at 15 µm/s for 0.2 s: every sample's
    # delay back one pitch is ceil(0.5e-6 * 4000 / 1.5e-5) = ceil(133.3) = 134.
    model = root / "examples/compensate/position_ripple/model_augmented.yaml"
    controller = root / "examples/compensate/position_ripple/controller.yaml"
    k = np.arange(800)
    rec = tmp_path / "alpha.csv"
    np.savetxt(rec, np.column_stack([k / 4000.0, 1.5e-5 * k / 4000.0, np.zeros(800)]),
               delimiter=",", header="t_s,stage.y,u", comments="", fmt="%.17g")
    c = nm.compensate(model, controller, measured_alpha=f"{rec}:stage.y", delay_margin=0.05)
    d = c.report["compensators"][0]["design"]
    n = np.ceil(0.5e-6 * 4000 / 1.5e-5)
    assert (d["delay_measured_min"], d["delay_measured_max"]) == (n, n)
    assert d["delay_margin"] == 0.05
    assert d["n_min"] == np.floor(n * 0.95) - 1
    # The same design as the command line's.
    out = tmp_path / "cli"
    p = run_cli(cli, "compensate", str(model), str(controller), "--out", str(out),
                "--measured-alpha", f"{rec}:stage.y", "--delay-margin", "0.05")
    assert p.returncode == 0, p.stderr
    assert json.loads((out / "report.json").read_text())["compensators"][0]["design"] == d
    # A column no delay-varying RC follows, and one the file does not have.
    with pytest.raises(nm.DiagnoseError, match="no delay-varying RC follows `u`"):
        nm.compensate(model, controller, measured_alpha=f"{rec}:u")
    with pytest.raises(nm.DiagnoseError, match="has no column `alpha.y`"):
        nm.compensate(model, controller, measured_alpha=f"{rec}:alpha.y")

//! RC blocks against their transfer functions (5.1) and M_HO, DVRC ≡ RC for α = t,
//! closed-loop suppression of a periodic disturbance, no allocation per tick.

use dvrc::filters::{Filter, FilterSpec};
use dvrc::rc::{Dvrc, HighOrderRc, MemoryLoop, RepetitiveControl};
use nalgebra::DMatrix;
use nanomotion_core::lti::{
    SsStepper, StateSpace, TransferFunction, delay, feedback, lsim_siso, parallel, series,
};
use nanomotion_core::{Block, BuildContext, LearningFilter, Tick};

const DT: f64 = 1.0 / 4000.0;

fn one() -> StateSpace {
    StateSpace::gain(DMatrix::from_element(1, 1, 1.0), Some(DT))
}

/// M(z) = L Q z^-(N−l−q) / (1 − Q W z^-(N−q)), W given as weights.
fn m_model(l: &Filter, q: &Filter, n: usize, weights: &[f64]) -> StateSpace {
    let (lp, qd) = (l.preview_samples(), q.preview_samples());
    let mut w = StateSpace::gain(DMatrix::zeros(1, 1), Some(DT));
    for (i, wi) in weights.iter().enumerate() {
        w = parallel(&w, &delay(i * n, DT).scaled(*wi)).unwrap();
    }
    let fwd = series(
        &series(&series(l.model().unwrap(), q.model().unwrap()).unwrap(), &w).unwrap(),
        &delay(n - lp - qd, DT),
    )
    .unwrap();
    let lp_loop = series(&series(q.model().unwrap(), &w).unwrap(), &delay(n - qd, DT)).unwrap();
    let sm = feedback(&one(), &lp_loop, 1.0).unwrap();
    series(&fwd, &sm).unwrap()
}

fn l_and_q() -> (FilterSpec, FilterSpec) {
    (
        // ZPETC of T(z) = 0.2 (z + 0.5)/((z − 0.6) z): preview 1.
        FilterSpec::Zpetc {
            num: vec![0.2, 0.1],
            den: vec![1.0, -0.6, 0.0],
        },
        FilterSpec::FirLowpass {
            taps: 7,
            cutoff_hz: 600.0,
        },
    )
}

#[test]
fn standard_and_high_order_rc_match_their_transfer_functions() {
    let (ls, qs) = l_and_q();
    let n = 17;
    let u: Vec<f64> = (0..300)
        .map(|k| ((k * 37 % 19) as f64 - 9.0) / 9.0)
        .collect();
    // Standard RC (5.1).
    let mut rc = RepetitiveControl::built(n, ls.clone(), qs.clone(), DT).unwrap();
    let y: Vec<f64> = u.iter().map(|&e| rc.step(e)).collect();
    let ml = rc.memory_loop().unwrap();
    let model = m_model(ml.learning(), ml.robustness(), n, &[1.0]);
    let y_ref = lsim_siso(&model, &u).unwrap();
    let scale = y_ref.iter().map(|v| v.abs()).fold(0.0, f64::max);
    assert!(scale > 0.5, "{scale}");
    for k in 0..u.len() {
        assert!(
            (y[k] - y_ref[k]).abs() < 1e-9 * scale,
            "k {k}: {} vs {}",
            y[k],
            y_ref[k]
        );
    }
    // High-order RC, W = 2 − z^-N.
    let mut ho = HighOrderRc::new(n, ls, qs);
    ho.build_dt(DT).unwrap();
    let y: Vec<f64> = u.iter().map(|&e| ho.step(e)).collect();
    let model = m_model(ml.learning(), ml.robustness(), n, &[2.0, -1.0]);
    let y_ref = lsim_siso(&model, &u).unwrap();
    for k in 0..u.len() {
        assert!(
            (y[k] - y_ref[k]).abs() < 1e-9 * scale.max(1.0),
            "k {k}: {} vs {}",
            y[k],
            y_ref[k]
        );
    }
}

/// Closed loop of Fig. 5.1 with T simulated directly: e = e_ext − T w.
struct Loop {
    t: SsStepper,
}

impl Loop {
    fn new(t: &StateSpace) -> Self {
        Self {
            t: SsStepper::new(t).unwrap(),
        }
    }
    fn error(&mut self, e_ext: f64, w: f64) -> f64 {
        e_ext - self.t.step_siso(w)
    }
}

fn t_model() -> StateSpace {
    TransferFunction::new(vec![0.2, 0.1], vec![1.0, -0.6, 0.0], Some(DT))
        .unwrap()
        .to_ss()
        .unwrap()
}

#[test]
fn dvrc_with_alpha_equal_time_is_standard_rc_bit_for_bit_in_closed_loop() {
    let (ls, qs) = l_and_q();
    let n = 80;
    let mut rc = RepetitiveControl::built(n, ls.clone(), qs.clone(), DT).unwrap();
    let mut dv = Dvrc::new(n as f64 * DT, 40, 120, ls, qs).with_n_init(n);
    // Through the Block interface, as a graph would run it.
    dv.build(&BuildContext::new("dvrc", DT, 0)).unwrap();
    let (mut l1, mut l2) = (Loop::new(&t_model()), Loop::new(&t_model()));
    let mut e1 = 0.0;
    let mut hist = Vec::new();
    let mut y = [0.0, 0.0];
    for k in 0..4000u64 {
        let tick = Tick::new(k, DT);
        let d = (2.0 * std::f64::consts::PI * k as f64 / n as f64).sin()
            + 0.4 * (6.0 * std::f64::consts::PI * k as f64 / n as f64 + 0.3).cos();
        // RC: output w_k (past only), then the loop gives e_k, then learn.
        let mut r1 = [0.0];
        <RepetitiveControl as Block>::output(&mut rc, tick, &[e1], &mut r1);
        e1 = l1.error(d, r1[0]);
        <RepetitiveControl as Block>::update(&mut rc, tick, &[e1]);
        // DVRC: w_k from α_k (two-phase Rust API), the loop's e_k, then learn;
        // and the same through the Block interface on a clone, in a graph's order.
        let alpha = k as f64 * DT;
        let mut as_block = dv.clone();
        let (w2, nk) = dv.output_w(alpha);
        let e2 = l2.error(d, w2);
        dv.learn(e2);
        as_block.output(tick, &[e2, alpha], &mut y);
        assert_eq!(nk, n);
        assert_eq!(y[1], n as f64);
        assert_eq!(y[0].to_bits(), w2.to_bits());
        assert_eq!(r1[0].to_bits(), w2.to_bits(), "k {k}");
        assert_eq!(e1.to_bits(), e2.to_bits());
        hist.push(e1);
    }
    // And the RC did its job: the periodic error is suppressed (to the level Q's
    // attenuation of the harmonics leaves).
    let peak = |x: &[f64]| x.iter().map(|v| v.abs()).fold(0.0, f64::max);
    let (first, last) = (peak(&hist[..80]), peak(&hist[hist.len() - 80..]));
    assert!(first > 1.0 && last < 0.02 * first, "{first} → {last}");
}

#[test]
fn rc_suppresses_a_periodic_disturbance_and_dvrc_a_rate_varying_one() {
    let (ls, qs) = l_and_q();
    let t = t_model();
    let n0 = 100.0;
    // Disturbance periodic in α, with α advancing at a varying rate:
    // α' = (2π/n0)(1 + 0.3 sin(2π k/3000)) per sample.
    let steps = 24000;
    let mut alpha = vec![0.0; steps];
    for k in 1..steps {
        alpha[k] = alpha[k - 1]
            + 2.0 * std::f64::consts::PI / n0
                * (1.0 + 0.3 * (2.0 * std::f64::consts::PI * k as f64 / 3000.0).sin());
    }
    let d: Vec<f64> = alpha
        .iter()
        .map(|a| a.sin() + 0.5 * (2.0 * a).cos())
        .collect();
    let rms_tail =
        |e: &[f64]| (e[steps / 2..].iter().map(|v| v * v).sum::<f64>() / (steps / 2) as f64).sqrt();
    // No RC.
    let mut lp = Loop::new(&t);
    let e0: Vec<f64> = d.iter().map(|&x| lp.error(x, 0.0)).collect();
    // Standard RC with the mean period.
    let mut rc = RepetitiveControl::built(100, ls.clone(), qs.clone(), DT).unwrap();
    let mut lp = Loop::new(&t);
    let mut e_rc = vec![];
    for &x in &d {
        let w = rc.output_w();
        let e = lp.error(x, w);
        rc.learn(e);
        e_rc.push(e);
    }
    // DVRC on α, N_k ∈ [60, 160] (rate ±30 %).
    let mut dv = Dvrc::new(2.0 * std::f64::consts::PI, 60, 160, ls, qs);
    dv.build_dt(DT).unwrap();
    let mut lp = Loop::new(&t);
    let mut e_dv = vec![];
    let mut n_seen = (usize::MAX, 0);
    for (k, &x) in d.iter().enumerate() {
        let (w, nk) = dv.output_w(alpha[k]);
        let e = lp.error(x, w);
        dv.learn(e);
        if k > 2000 {
            n_seen = (n_seen.0.min(nk), n_seen.1.max(nk));
        }
        e_dv.push(e);
    }
    let (r0, r_rc, r_dv) = (rms_tail(&e0), rms_tail(&e_rc), rms_tail(&e_dv));
    // The period in samples is 100/(1 + 0.3 sin) ∈ [77, 143].
    assert!(
        n_seen.0 >= 76 && n_seen.0 <= 80 && n_seen.1 >= 140 && n_seen.1 <= 145,
        "{n_seen:?}"
    );
    assert!(r0 > 0.3, "{r0}");
    assert!(r_dv < 0.05 * r0, "DVRC {r_dv} vs none {r0}");
    assert!(r_dv < 0.2 * r_rc, "DVRC {r_dv} vs RC {r_rc}");
}

#[test]
fn memory_loop_tick_does_not_allocate() {
    let (ls, _) = l_and_q();
    let mut dv = Dvrc::new(
        2.0 * std::f64::consts::PI,
        60,
        4000,
        ls,
        FilterSpec::q_fir(101, 300.0),
    );
    dv.build_dt(DT).unwrap();
    let mut rc =
        RepetitiveControl::built(500, FilterSpec::Identity, FilterSpec::q_fir(101, 300.0), DT)
            .unwrap();
    let mut ho = HighOrderRc::new(500, FilterSpec::Identity, FilterSpec::q_fir(101, 300.0));
    ho.build_dt(DT).unwrap();
    let info = allocation_counter::measure(|| {
        let mut a = 0.0;
        for k in 0..20000 {
            // α with stalls and reversals to exercise every path.
            a += if (k / 3000) % 3 == 2 {
                -0.002
            } else if k % 7 == 0 {
                0.0
            } else {
                0.01
            };
            let e = (k as f64 * 0.01).sin();
            std::hint::black_box(dv.step(e, a));
            std::hint::black_box(rc.step(e));
            std::hint::black_box(ho.step(e));
        }
    });
    assert_eq!(info.count_total, 0);
    let ml: &MemoryLoop = dv.memory_loop().unwrap();
    assert_eq!(ml.buffer_len(), 4000 - 50 - 1 + 1);
}

#[test]
fn yaml_blocks_parse_validate_and_name_the_field() {
    let b: Box<dyn Block> = nanomotion_core::yaml::from_str(
        "type: dvrc\nn_min: 10\nn_max: 40\nrobustness: {kind: fir_lowpass, taps: 21, cutoff_hz: 100}\n",
        "t",
    )
    .unwrap();
    let mut b = b;
    let e = b.build(&BuildContext::new("rc", DT, 0)).unwrap_err();
    assert_eq!(e.field, "n_min");
    assert!(e.fix.contains("11"), "{e}");
    let mut ok: Box<dyn Block> = nanomotion_core::yaml::from_str(
        "type: high_order_rc\nn: 40\nweights: [2.0, -1.0]\nrobustness: {kind: fir_lowpass, taps: 21, cutoff_hz: 100}\n",
        "t",
    )
    .unwrap();
    ok.build(&BuildContext::new("ho", DT, 0)).unwrap();
    assert!(!ok.direct_feedthrough());
    assert_eq!(ok.outputs()[0].name, "w");
    let mut rc: Box<dyn Block> =
        nanomotion_core::yaml::from_str("type: repetitive_control\nn: 5\n", "t").unwrap();
    rc.build(&BuildContext::new("rc", DT, 0)).unwrap();
    let e = nanomotion_core::yaml::from_str::<Box<dyn Block>>(
        "type: repetitive_control\nn: 5\nfoo: 1\n",
        "t",
    );
    assert!(e.is_err());
}

#[test]
fn period_is_estimated_from_the_error() {
    let t = t_model();
    let mut lp = Loop::new(&t);
    let e: Vec<f64> = (0..8000)
        .map(|k| {
            let ph = 2.0 * std::f64::consts::PI * k as f64 / 221.0;
            lp.error(
                ph.sin() + 0.7 * (2.0 * ph).sin() + 0.2 * (5.0 * ph).cos(),
                0.0,
            )
        })
        .collect();
    assert_eq!(dvrc::estimate_period_samples(&e, 50, 1000), Some(221));
    let l = FilterSpec::Identity.build(DT).unwrap();
    assert_eq!(l.preview_samples(), 0);
}

//! Time per call of the dense LTI numerics at n = 10, 20, 40 (issue 14):
//! `cargo bench -p nanomotion-core --bench lti_numerics`.
//!
//! Issue 29: `hinf_ratio` times `hinfnorm` and its previous implementation
//! (`hinfnorm_schur_eigensolver`) side by side at n = 10 … 80, and `eig`
//! the eigenvalue-only QR iteration (`eigvals_fast`) against nalgebra's Schur
//! form (`eigvals`) at n = 100 … 400, so their ratios come from one run:
//! `cargo bench -p nanomotion-core --bench lti_numerics -- 'hinf_ratio|eig/'`.
//! The `hinf_ratio` systems come from `nanomotion_core::lti::random_systems`, shared with
//! the `hinf_systems` example that `tools/hinfnorm_vs_ab13dd.py` runs to time
//! SLICOT's `ab13dd` on the same matrices.

use criterion::measurement::WallTime;
use criterion::{BenchmarkGroup, Criterion, criterion_group, criterion_main};
use nalgebra::DMatrix;
use nanomotion_core::lti::hinf::hinfnorm_schur_eigensolver;
use nanomotion_core::lti::hinfsyn::{HinfSynOptions, augw, hinfsyn};
use nanomotion_core::lti::linalg::{eigvals, eigvals_fast};
use nanomotion_core::lti::{StateSpace, care, dare, hinfnorm, lyap};
use nanomotion_core::rng::Rng;
use std::hint::black_box;
use std::time::Duration;

use nanomotion_core::lti::random_systems::{hinf_ratio_systems, hurwitz, random};

/// A group of 10 samples, 0.3 s warm-up and 1 s of measurement: every
/// group of this bench is timed alike.
fn quick_group<'a>(c: &'a mut Criterion, name: &str) -> BenchmarkGroup<'a, WallTime> {
    let mut group = c.benchmark_group(name);
    group
        .sample_size(10)
        .warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_secs(1));
    group
}

fn bench(c: &mut Criterion) {
    let mut group = quick_group(c, "lti");
    for n in [10usize, 20, 40] {
        let mut rng = Rng::new(n as u64);
        let a = random(&mut rng, n, n);
        let b = random(&mut rng, n, 2);
        let q = DMatrix::identity(n, n);
        let r = DMatrix::identity(2, 2);
        group.bench_function(format!("care/{n}"), |bch| {
            bch.iter(|| care(black_box(&a), &b, &q, &r, None).unwrap())
        });
        let rho = eigvals(&a).iter().map(|p| p.norm()).fold(0.0, f64::max);
        let ad = &a * (1.1 / rho);
        group.bench_function(format!("dare/{n}"), |bch| {
            bch.iter(|| dare(black_box(&ad), &b, &q, &r, None).unwrap())
        });
        let ah = hurwitz(&mut rng, n);
        group.bench_function(format!("lyap/{n}"), |bch| {
            bch.iter(|| lyap(black_box(&ah), &q).unwrap())
        });
        let sys = StateSpace::new(
            ah.clone(),
            random(&mut rng, n, 2),
            random(&mut rng, 2, n),
            DMatrix::zeros(2, 2),
            None,
        )
        .unwrap();
        group.bench_function(format!("hinfnorm/{n}"), |bch| {
            bch.iter(|| hinfnorm(black_box(&sys)).unwrap())
        });
        // Mixed sensitivity on a stable plant of n − 2 states (P has n states:
        // plant, W1 of order 1, W2 static... plus one more weight state).
        let ng = n - 2;
        let g = StateSpace::new(
            hurwitz(&mut rng, ng),
            random(&mut rng, ng, 1),
            random(&mut rng, 1, ng),
            DMatrix::zeros(1, 1),
            None,
        )
        .unwrap();
        let w1 = StateSpace::new(
            DMatrix::from_element(1, 1, -0.01),
            DMatrix::from_element(1, 1, 1.0),
            DMatrix::from_element(1, 1, 1.0),
            DMatrix::zeros(1, 1),
            None,
        )
        .unwrap();
        let w2 = StateSpace::new(
            DMatrix::from_element(1, 1, -100.0),
            DMatrix::from_element(1, 1, 100.0),
            DMatrix::from_element(1, 1, 1.0),
            DMatrix::from_element(1, 1, 0.1),
            None,
        )
        .unwrap();
        let p = augw(&g, Some(&w1), Some(&w2), None).unwrap();
        assert_eq!(p.nstates(), n);
        group.bench_function(format!("hinfsyn/{n}"), |bch| {
            bch.iter(|| hinfsyn(black_box(&p), 1, 1, &HinfSynOptions::default()).unwrap())
        });
    }
    group.finish();
}

/// `hinfnorm` before and after issue 29 at n = 10 … 80 (2 × 2, continuous
/// and discrete), and the eigenvalue solvers at n = 100 … 400.
fn issue_29(c: &mut Criterion) {
    let mut group = quick_group(c, "hinf_ratio");
    for (name, sys) in hinf_ratio_systems() {
        group.bench_function(format!("after/{name}"), |bch| {
            bch.iter(|| hinfnorm(black_box(&sys)).unwrap())
        });
        group.bench_function(format!("before/{name}"), |bch| {
            bch.iter(|| hinfnorm_schur_eigensolver(black_box(&sys)).unwrap())
        });
    }
    group.finish();
    let mut group = quick_group(c, "eig");
    for n in [100usize, 200, 400] {
        let a = random(&mut Rng::new(n as u64), n, n);
        group.bench_function(format!("eigvals_fast/{n}"), |bch| {
            bch.iter(|| eigvals_fast(black_box(&a)))
        });
        group.bench_function(format!("eigvals/{n}"), |bch| {
            bch.iter(|| eigvals(black_box(&a)))
        });
    }
    group.finish();
}

criterion_group!(benches, bench, issue_29);
criterion_main!(benches);

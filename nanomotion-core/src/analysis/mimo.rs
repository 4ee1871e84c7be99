//! MIMO frequency-domain analysis (Ch. 6–7 of the thesis): multivariable FRF
//! estimation, the relative gain array (6.2) and characteristic loci.
//!
//! Matrices are `nalgebra::DMatrix<Complex<f64>>`, one per frequency bin.

use super::{AnalysisError, Complex, SpectralMatrix, WelchOptions};
use nalgebra::DMatrix;

/// A complex matrix (one frequency bin of a MIMO FRF).
pub type CMatrix = DMatrix<Complex<f64>>;

/// Relative gain array Λ = G ∘ (G⁻¹)ᵀ (element-wise product), thesis (6.2).
/// Each row and column of Λ sums to 1; Λ = I for a decoupled (diagonal) plant.
///
/// ```
/// use nanomotion_core::analysis::{mimo::rga, Complex};
/// use nalgebra::DMatrix;
/// let c = |x: f64| Complex::new(x, 0.0);
/// let g = DMatrix::from_row_slice(2, 2, &[c(1.0), c(0.5), c(0.5), c(1.0)]);
/// let l = rga(&g).unwrap();
/// // λ11 = 1 / (1 − g12 g21 / (g11 g22)) = 4/3.
/// assert!((l[(0, 0)].re - 4.0 / 3.0).abs() < 1e-12);
/// ```
pub fn rga(g: &CMatrix) -> Result<CMatrix, AnalysisError> {
    if !g.is_square() || g.nrows() == 0 {
        return Err(AnalysisError::param(
            "g",
            "the RGA needs a non-empty square matrix",
        ));
    }
    let inv = g
        .clone()
        .try_inverse()
        .ok_or_else(|| AnalysisError::param("g", "singular matrix has no RGA"))?;
    Ok(g.component_mul(&inv.transpose()))
}

/// Eigenvalues of a complex square matrix (diagonal of its complex Schur form).
pub fn eigenvalues(m: &CMatrix) -> Result<Vec<Complex<f64>>, AnalysisError> {
    if !m.is_square() {
        return Err(AnalysisError::param(
            "m",
            "eigenvalues need a square matrix",
        ));
    }
    if m.nrows() == 0 {
        return Ok(Vec::new());
    }
    let schur = nalgebra::Schur::try_new(m.clone(), 1e-14, 10_000)
        .ok_or_else(|| AnalysisError::param("m", "Schur decomposition did not converge"))?;
    let (_, t) = schur.unpack();
    Ok((0..t.nrows()).map(|i| t[(i, i)]).collect())
}

/// Characteristic loci: the eigenvalues λ_i(L(f_k)) of the loop-gain matrices
/// `l[k]`, one locus per eigenvalue (`result[i][k]`). The eigenvalues are matched
/// from one frequency to the next by nearest distance, so that each locus is a
/// continuous curve when the grid is fine enough. The generalised Nyquist
/// criterion counts the encirclements of −1 by all loci together.
pub fn characteristic_loci(l: &[CMatrix]) -> Result<Vec<Vec<Complex<f64>>>, AnalysisError> {
    let Some(first) = l.first() else {
        return Ok(Vec::new());
    };
    let n = first.nrows();
    let mut loci: Vec<Vec<Complex<f64>>> = vec![Vec::with_capacity(l.len()); n];
    for m in l {
        if m.nrows() != n || m.ncols() != n {
            return Err(AnalysisError::param("l", "all matrices must be n × n"));
        }
        let mut ev = eigenvalues(m)?;
        if loci[0].is_empty() {
            for (locus, e) in loci.iter_mut().zip(ev) {
                locus.push(e);
            }
            continue;
        }
        // Greedy nearest matching: repeatedly take the closest (locus, eigenvalue) pair.
        let mut assigned = vec![None; n];
        for _ in 0..n {
            let mut best = (f64::INFINITY, 0, 0);
            for (i, locus) in loci.iter().enumerate() {
                if assigned[i].is_some() {
                    continue;
                }
                let last = *locus.last().expect("non-empty after the first bin");
                for (j, e) in ev.iter().enumerate() {
                    let d = (e - last).norm();
                    if d < best.0 {
                        best = (d, i, j);
                    }
                }
            }
            let (_, i, j) = best;
            assigned[i] = Some(ev.swap_remove(j));
        }
        for (locus, e) in loci.iter_mut().zip(assigned) {
            locus.push(e.expect("every locus assigned"));
        }
    }
    Ok(loci)
}

/// MIMO H1 estimate H(f) = (S_uu⁻¹ S_uy)ᵀ from m inputs and p outputs measured
/// together (the inputs must be jointly exciting, e.g. independent noises on all
/// inputs at once): returns one p × m matrix per bin, H[(j, i)] from input i to
/// output j, and the bin frequencies in Hz. Bins where S_uu is singular give a
/// zero matrix.
pub fn frf_mimo_h1(
    inputs: &[&[f64]],
    outputs: &[&[f64]],
    fs_hz: f64,
    opts: &WelchOptions,
) -> Result<(Vec<f64>, Vec<CMatrix>), AnalysisError> {
    let (m, p) = (inputs.len(), outputs.len());
    if m == 0 || p == 0 {
        return Err(AnalysisError::TooShort(
            "need at least one input and one output".into(),
        ));
    }
    let signals: Vec<&[f64]> = inputs.iter().chain(outputs).copied().collect();
    let s = SpectralMatrix::compute(&signals, fs_hz, opts)?;
    let nb = s.freq_hz.len();
    let cross: Vec<Vec<Vec<Complex<f64>>>> = (0..m)
        .map(|i| (0..m + p).map(|j| s.cross(i, j)).collect())
        .collect();
    let h = (0..nb)
        .map(|k| {
            let suu = CMatrix::from_fn(m, m, |i, j| cross[i][j][k]);
            let suy = CMatrix::from_fn(m, p, |i, j| cross[i][m + j][k]);
            match suu.lu().solve(&suy) {
                Some(x) => x.transpose(),
                None => CMatrix::zeros(p, m),
            }
        })
        .collect();
    Ok((s.freq_hz, h))
}

/// MIMO closed-loop identification from noise injected at all plant inputs
/// (the MIMO form of Fig. 2.8): with Ŝ the FRF from the injected noises to the plant
/// inputs and Ŝ_P the FRF to the plant outputs, P̂ = Ŝ_P Ŝ⁻¹ per bin (zero where Ŝ is
/// singular). Returns the frequencies in Hz and the p × m plant matrices.
pub fn frf_mimo_closed_loop(
    noises: &[&[f64]],
    plant_inputs: &[&[f64]],
    plant_outputs: &[&[f64]],
    fs_hz: f64,
    opts: &WelchOptions,
) -> Result<(Vec<f64>, Vec<CMatrix>), AnalysisError> {
    if plant_inputs.len() != noises.len() {
        return Err(AnalysisError::Length(noises.len(), plant_inputs.len()));
    }
    let both: Vec<&[f64]> = plant_inputs.iter().chain(plant_outputs).copied().collect();
    let (f, h) = frf_mimo_h1(noises, &both, fs_hz, opts)?;
    let m = noises.len();
    let p = plant_outputs.len();
    let plant = h
        .into_iter()
        .map(|hk| {
            let s = hk.rows(0, m).into_owned();
            let sp = hk.rows(m, p).into_owned();
            // P = S_P S⁻¹  ⇔  Sᵀ Pᵀ = S_Pᵀ.
            match s.transpose().lu().solve(&sp.transpose()) {
                Some(pt) => pt.transpose(),
                None => CMatrix::zeros(p, m),
            }
        })
        .collect();
    Ok((f, plant))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;
    use std::f64::consts::TAU;

    fn c(re: f64, im: f64) -> Complex<f64> {
        Complex::new(re, im)
    }

    #[test]
    fn rga_closed_form_and_sums() {
        let g = CMatrix::from_row_slice(
            2,
            2,
            &[c(2.0, 1.0), c(0.3, -0.2), c(-0.4, 0.1), c(1.0, 0.5)],
        );
        let l = rga(&g).unwrap();
        let l11 = c(1.0, 0.0) / (c(1.0, 0.0) - g[(0, 1)] * g[(1, 0)] / (g[(0, 0)] * g[(1, 1)]));
        assert!((l[(0, 0)] - l11).norm() < 1e-12);
        assert!((l[(1, 1)] - l11).norm() < 1e-12);
        assert!((l[(0, 1)] - (c(1.0, 0.0) - l11)).norm() < 1e-12);
        // 3 × 3: rows and columns sum to one; diagonal plant → identity.
        let mut rng = Rng::new(31);
        let g3 = CMatrix::from_fn(3, 3, |_, _| c(rng.normal(), rng.normal()));
        let l3 = rga(&g3).unwrap();
        for i in 0..3 {
            assert!((l3.row(i).sum() - c(1.0, 0.0)).norm() < 1e-10);
            assert!((l3.column(i).sum() - c(1.0, 0.0)).norm() < 1e-10);
        }
        let d =
            CMatrix::from_diagonal(&nalgebra::DVector::from_vec(vec![c(2.0, 0.0), c(0.0, 3.0)]));
        assert!((rga(&d).unwrap() - CMatrix::identity(2, 2)).norm() < 1e-15);
        assert!(rga(&CMatrix::zeros(2, 2)).is_err());
        assert!(rga(&CMatrix::zeros(2, 3)).is_err());
    }

    #[test]
    fn eigenvalues_match_trace_and_determinant() {
        let mut rng = Rng::new(32);
        for n in [1, 2, 3, 5] {
            let m = CMatrix::from_fn(n, n, |_, _| c(rng.normal(), rng.normal()));
            let ev = eigenvalues(&m).unwrap();
            let sum: Complex<f64> = ev.iter().sum();
            let prod: Complex<f64> = ev.iter().product();
            assert!((sum - m.trace()).norm() < 1e-10, "n = {n}");
            assert!(
                (prod - m.determinant()).norm() < 1e-9 * (1.0 + prod.norm()),
                "n = {n}"
            );
            // Each is a root of det(m − λI).
            for e in &ev {
                let shifted = &m - CMatrix::identity(n, n) * *e;
                assert!(shifted.determinant().norm() < 1e-8, "n = {n}");
            }
        }
        // A real rotation has eigenvalues e^{±jθ}.
        let th: f64 = 0.3;
        let r = CMatrix::from_row_slice(
            2,
            2,
            &[
                c(th.cos(), 0.0),
                c(-th.sin(), 0.0),
                c(th.sin(), 0.0),
                c(th.cos(), 0.0),
            ],
        );
        let mut ev = eigenvalues(&r).unwrap();
        ev.sort_by(|a, b| a.im.total_cmp(&b.im));
        assert!((ev[0] - Complex::from_polar(1.0, -th)).norm() < 1e-12);
        assert!((ev[1] - Complex::from_polar(1.0, th)).norm() < 1e-12);
    }

    #[test]
    fn characteristic_loci_of_a_diagonal_system_are_its_diagonal() {
        // L(jω) = diag(1/(jω), 2/(jω + 1)) rotated by a constant similarity: the loci
        // are the diagonal responses, continuous across the crossing at |λ| equal.
        let t =
            CMatrix::from_row_slice(2, 2, &[c(1.0, 0.0), c(0.5, 0.0), c(0.2, 0.0), c(1.0, 0.0)]);
        let ti = t.clone().try_inverse().unwrap();
        let w: Vec<f64> = (1..400).map(|k| 0.01 * k as f64).collect();
        let l: Vec<CMatrix> = w
            .iter()
            .map(|&w| {
                let d = CMatrix::from_diagonal(&nalgebra::DVector::from_vec(vec![
                    c(1.0, 0.0) / c(0.0, w),
                    c(2.0, 0.0) / c(1.0, w),
                ]));
                &t * d * &ti
            })
            .collect();
        let loci = characteristic_loci(&l).unwrap();
        assert_eq!(loci.len(), 2);
        // Identify which locus starts near 1/(jω₀).
        let first = c(1.0, 0.0) / c(0.0, w[0]);
        let (a, b) = if (loci[0][0] - first).norm() < (loci[1][0] - first).norm() {
            (0, 1)
        } else {
            (1, 0)
        };
        for (k, &wk) in w.iter().enumerate() {
            assert!((loci[a][k] - c(1.0, 0.0) / c(0.0, wk)).norm() < 1e-9);
            assert!((loci[b][k] - c(2.0, 0.0) / c(1.0, wk)).norm() < 1e-9);
        }
        assert!(characteristic_loci(&[]).unwrap().is_empty());
    }

    /// y_j[k] = Σ_i g_ji u_i[k − d_ji]: a 2 × 2 system of gains and delays.
    fn exact(g: &[[f64; 2]; 2], d: &[[usize; 2]; 2], f: f64, fs: f64) -> CMatrix {
        CMatrix::from_fn(2, 2, |j, i| {
            Complex::from_polar(g[j][i], -TAU * f * d[j][i] as f64 / fs)
        })
    }

    #[test]
    #[allow(clippy::needless_range_loop)] // a simulation indexed by channel and time
    fn mimo_h1_and_closed_loop_recover_a_coupled_plant() {
        let fs = 1000.0;
        let g = [[1.0, 0.3], [-0.2, 0.8]];
        let dl = [[1, 2], [3, 1]];
        let n = 1 << 16;
        let mut rng = Rng::new(33);
        let opts = WelchOptions::new(256);
        let out = |u: &[Vec<f64>], k: usize, j: usize| -> f64 {
            (0..2)
                .map(|i| {
                    if k >= dl[j][i] {
                        g[j][i] * u[i][k - dl[j][i]]
                    } else {
                        0.0
                    }
                })
                .sum()
        };
        // Open loop: independent noises on both inputs.
        let u: Vec<Vec<f64>> = (0..2)
            .map(|_| (0..n).map(|_| rng.normal()).collect())
            .collect();
        let y: Vec<Vec<f64>> = (0..2)
            .map(|j| (0..n).map(|k| out(&u, k, j)).collect())
            .collect();
        let (f, h) = frf_mimo_h1(&[&u[0], &u[1]], &[&y[0], &y[1]], fs, &opts).unwrap();
        for k in (1..100).step_by(7) {
            let e = exact(&g, &dl, f[k], fs);
            assert!(
                (&h[k] - &e).norm() < 0.05,
                "bin {k}: {}",
                (&h[k] - &e).norm()
            );
        }
        // Closed loop: u = d − K y with a diagonal static controller K = 0.5 I.
        let mut rng = Rng::new(34);
        let d: Vec<Vec<f64>> = (0..2)
            .map(|_| (0..n).map(|_| rng.normal()).collect())
            .collect();
        let mut u = vec![vec![0.0; n]; 2];
        let mut y = vec![vec![0.0; n]; 2];
        for k in 0..n {
            for j in 0..2 {
                y[j][k] = out(&u, k, j) + 0.3 * rng.normal();
            }
            for i in 0..2 {
                u[i][k] = d[i][k] - 0.5 * y[i][k];
            }
        }
        let (f, p) =
            frf_mimo_closed_loop(&[&d[0], &d[1]], &[&u[0], &u[1]], &[&y[0], &y[1]], fs, &opts)
                .unwrap();
        let (_, naive) = frf_mimo_h1(&[&u[0], &u[1]], &[&y[0], &y[1]], fs, &opts).unwrap();
        let (mut worst_cl, mut worst_naive) = (0.0f64, 0.0f64);
        for k in 1..100 {
            let e = exact(&g, &dl, f[k], fs);
            worst_cl = worst_cl.max((&p[k] - &e).norm());
            worst_naive = worst_naive.max((&naive[k] - &e).norm());
        }
        assert!(worst_cl < 0.1, "closed loop: {worst_cl}");
        assert!(
            worst_naive > 0.1,
            "naive H1 should be biased: {worst_naive}"
        );
    }
}

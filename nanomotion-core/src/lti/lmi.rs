//! A small dense LMI feasibility solver.
//!
//! Problems of the form: find symmetric matrices X₁ … X_p such that
//!
//! ```text
//! F_k(X) = C_k + Σ_s c_s·(L_sᵀ X_{v(s)} R_s + R_sᵀ X_{v(s)} L_s)/2 ≻ 0,   k = 1 … K,
//! ```
//!
//! every F_k affine in the X_i: a symmetric constant plus congruence terms c·AᵀXA
//! ([`LmiConstraint::congruence`], L = R = A), plain terms c·X
//! ([`LmiConstraint::var`]) and symmetrised products c·(LᵀXR + RᵀXL)
//! ([`LmiConstraint::sym_product`], for off-diagonal blocks such as the P_jΛ of the
//! thesis's (5.16)). That covers discrete Lyapunov inequalities AᵀPA − P ≺ 0,
//! common and parameter-dependent Lyapunov functions of switched systems
//! (Merry 2009, (5.16)), and their 2×2-block (Schur complement) forms.
//!
//! # Method
//!
//! The phase-I problem
//!
//! ```text
//! maximise t  subject to  F_k(X) − t·I ⪰ 0 (all k),   −R·I ⪯ X_i ⪯ R·I (all i)
//! ```
//!
//! with R = [`LmiOptions::bound`] (so the problem is bounded) is solved by a primal
//! log-det barrier path-following method (Boyd & Vandenberghe, *Convex
//! Optimization*, §11.3 and §11.6): minimise −s·t − Σ log det(·) over all the
//! matrix inequalities, by damped Newton steps with the exact gradient
//! −tr(F⁻¹ ∂F) and Hessian tr(F⁻¹ ∂_jF F⁻¹ ∂_lF) (assembled per pair of terms
//! from products R W Lᵀ, W = F⁻¹, in O(1) per entry), solved by Cholesky, a
//! backtracking line search that keeps every iterate strictly feasible (checked by
//! Cholesky), then s ← μ·s. Each F_k is normalised by a bound on its size (so the
//! `t` of different constraints are comparable); margins are reported unscaled.
//!
//! - **Feasible**: as soon as an iterate has t > 0, the X_i are checked
//!   *independently* of the solver: every F_k(X) is rebuilt from the data and its
//!   smallest eigenvalue computed (symmetric eigen-decomposition); the answer is
//!   [`LmiStatus::Feasible`] only if all are above a round-off threshold. The
//!   returned [`LmiSolution::margin`] is that verified min_k λ_min(F_k(X)).
//! - **Not feasible**: on the central path the optimum satisfies
//!   t* ≤ t(s) + ν/s (ν the total size of all barrier matrices, the duality gap of
//!   the log-det barrier). When this upper bound is < 0 there is no X with
//!   ‖X_i‖ ≤ R satisfying the LMIs ([`LmiStatus::Infeasible`], up to the centring
//!   accuracy). **Homogeneous** problems (no constant terms, such as Lyapunov
//!   LMIs) always have t* ≥ 0 (X = 0); for them the bound R loses no generality
//!   (scaling X scales every F_k) and the answer is
//!   [`LmiStatus::InfeasibleWithinTolerance`]: the gap closed below
//!   [`LmiOptions::gap_tol`] and no X reaches a normalised margin above
//!   [`LmiSolution::t_upper`] (infeasible, or feasible only with a margin below
//!   the tolerance, e.g. a spectral radius of exactly 1).
//! - **Undecided**: the Newton budget ran out.
//!
//! # Limits
//!
//! Dense and direct: the Newton system has one row per scalar unknown
//! (n(n+1)/2 per n×n variable), so cost grows like (unknowns)³ per step. Observed:
//! 8–30 Newton steps to a feasible certificate, 60–80 to close the gap on an
//! infeasible problem; 45 unknowns take ~3 ms, 480 unknowns (four 15×15
//! variables, twenty 15×15 LMIs) ~0.4 s at the test profile. Good for tens to a
//! few hundred unknowns and constraint matrices up to a few tens of rows;
//! [`LmiOptions::max_unknowns`] refuses larger problems. Only strict
//! inequalities ≻ 0; no equality constraints and no objective. Infeasibility is
//! established to a tolerance, not by an exact dual certificate (a strict
//! alternative system can be posed as another LMI problem, as the tests do for a
//! common Lyapunov function).
//!
//! ```
//! use nalgebra::DMatrix;
//! use nanomotion_core::lti::lmi::{LmiConstraint, LmiOptions, LmiProblem, LmiStatus};
//! // Discrete Lyapunov: find P ≻ 0 with P − AᵀPA ≻ 0 (A Schur).
//! let a = DMatrix::from_row_slice(2, 2, &[0.5, 1.0, 0.0, 0.8]);
//! let mut lmi = LmiProblem::new();
//! let p = lmi.variable("P", 2).unwrap();
//! let mut pos = LmiConstraint::new("P ≻ 0", 2);
//! pos.var(p, 1.0).unwrap();
//! lmi.add(pos).unwrap();
//! let mut dec = LmiConstraint::new("P − AᵀPA ≻ 0", 2);
//! dec.var(p, 1.0).unwrap().congruence(p, &a, -1.0).unwrap();
//! lmi.add(dec).unwrap();
//! let sol = lmi.solve(&LmiOptions::default()).unwrap();
//! assert_eq!(sol.status, LmiStatus::Feasible);
//! assert!(sol.margin > 0.0);
//! // The certificate, re-checked from the data.
//! assert!(lmi.min_eigenvalues(&sol.variables).unwrap().iter().all(|&e| e > 0.0));
//! ```

use nalgebra::{DMatrix, DVector};
use std::fmt;
use thiserror::Error;

/// What can go wrong when building or solving an LMI problem.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum LmiError {
    /// A matrix has the wrong size.
    #[error("dimension mismatch in {context}: {problem}")]
    Dimension {
        /// Where (constraint / variable / term).
        context: String,
        /// What does not fit, and the expected size.
        problem: String,
    },
    /// A matrix or coefficient contains NaN or ±∞.
    #[error("non-finite value in {0}: every entry must be finite")]
    NonFinite(String),
    /// A constant term that is not symmetric.
    #[error("constant of constraint `{0}` is not symmetric: pass a symmetric matrix")]
    NotSymmetric(String),
    /// A variable handle from another problem.
    #[error("unknown variable #{0}: declare it with LmiProblem::variable on this problem")]
    UnknownVariable(usize),
    /// The problem has no constraints or no variables, or a zero-sized one.
    #[error("empty problem: {0}")]
    Empty(String),
    /// An option is out of range.
    #[error("invalid option `{name}`: {problem}")]
    Option {
        /// Option name.
        name: &'static str,
        /// What is wrong.
        problem: String,
    },
    /// More scalar unknowns than [`LmiOptions::max_unknowns`].
    #[error(
        "problem too large: {unknowns} scalar unknowns > limit {limit} (dense Newton system; raise LmiOptions::max_unknowns or reduce the problem)"
    )]
    TooLarge {
        /// Scalar unknowns of the problem.
        unknowns: usize,
        /// The limit.
        limit: usize,
    },
}

/// Handle of a symmetric matrix variable, returned by [`LmiProblem::variable`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct LmiVar(usize);

impl LmiVar {
    /// Position of the variable in [`LmiSolution::variables`].
    pub fn index(self) -> usize {
        self.0
    }
}

/// One term c/2·(Lᵀ X R + Rᵀ X L) (L = R for a congruence term).
#[derive(Debug, Clone)]
struct Term {
    var: usize,
    l: DMatrix<f64>,
    r: DMatrix<f64>,
    c: f64,
    congruence: bool,
}

/// One strict LMI F(X) = C + Σ terms ≻ 0 of size `dim`, built term by term and
/// added with [`LmiProblem::add`] (which checks the term sizes against the
/// variables).
#[derive(Debug, Clone)]
pub struct LmiConstraint {
    name: String,
    dim: usize,
    constant: DMatrix<f64>,
    terms: Vec<Term>,
}

fn check_finite(m: &DMatrix<f64>, what: impl FnOnce() -> String) -> Result<(), LmiError> {
    if m.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(LmiError::NonFinite(what()))
    }
}

impl LmiConstraint {
    /// Largest constraint size accepted (a dense `dim` × `dim` matrix per term).
    pub const MAX_DIM: usize = 2048;

    /// A new constraint F ≻ 0 with F of size `dim` × `dim`, initially F = 0.
    /// `name` appears in errors and in [`LmiSolution::min_eigs`] order. A size of
    /// 0 or above [`Self::MAX_DIM`] is reported by the term methods and by
    /// [`LmiProblem::add`].
    pub fn new(name: impl Into<String>, dim: usize) -> Self {
        let alloc = if dim <= Self::MAX_DIM { dim } else { 0 };
        Self {
            name: name.into(),
            dim,
            constant: DMatrix::zeros(alloc, alloc),
            terms: Vec::new(),
        }
    }

    fn check_size(&self) -> Result<(), LmiError> {
        if self.dim > Self::MAX_DIM {
            return Err(LmiError::Dimension {
                context: format!("constraint `{}`", self.name),
                problem: format!("size {} > {} (dense solver)", self.dim, Self::MAX_DIM),
            });
        }
        Ok(())
    }

    /// The constraint's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Size of F.
    pub fn dim(&self) -> usize {
        self.dim
    }

    fn check_coef(&self, c: f64) -> Result<(), LmiError> {
        self.check_size()?;
        if c.is_finite() {
            Ok(())
        } else {
            Err(LmiError::NonFinite(format!(
                "coefficient of a term of constraint `{}`",
                self.name
            )))
        }
    }

    /// Add a symmetric constant matrix (`dim` × `dim`; symmetric to 1e-10
    /// relative, then symmetrised exactly).
    pub fn constant(&mut self, c: &DMatrix<f64>) -> Result<&mut Self, LmiError> {
        self.check_size()?;
        if c.nrows() != self.dim || c.ncols() != self.dim {
            return Err(LmiError::Dimension {
                context: format!("constant of constraint `{}`", self.name),
                problem: format!(
                    "{}×{}, expected {}×{}",
                    c.nrows(),
                    c.ncols(),
                    self.dim,
                    self.dim
                ),
            });
        }
        check_finite(c, || format!("constant of constraint `{}`", self.name))?;
        let asym = (c - c.transpose()).amax();
        if asym > 1e-10 * c.amax().max(f64::MIN_POSITIVE) {
            return Err(LmiError::NotSymmetric(self.name.clone()));
        }
        self.constant += (c + c.transpose()) * 0.5;
        Ok(self)
    }

    /// Add `coef`·I.
    pub fn identity(&mut self, coef: f64) -> Result<&mut Self, LmiError> {
        self.check_coef(coef)?;
        for i in 0..self.dim {
            self.constant[(i, i)] += coef;
        }
        Ok(self)
    }

    /// Add `coef`·X (X must be `dim` × `dim`; checked by [`LmiProblem::add`]).
    pub fn var(&mut self, x: LmiVar, coef: f64) -> Result<&mut Self, LmiError> {
        self.check_coef(coef)?;
        let i = DMatrix::identity(self.dim, self.dim);
        self.terms.push(Term {
            var: x.0,
            l: i.clone(),
            r: i,
            c: coef,
            congruence: true,
        });
        Ok(self)
    }

    /// Add `coef`·AᵀXA with A of size n × `dim` (n the size of X).
    pub fn congruence(
        &mut self,
        x: LmiVar,
        a: &DMatrix<f64>,
        coef: f64,
    ) -> Result<&mut Self, LmiError> {
        self.check_coef(coef)?;
        self.check_cols(a, "A of a congruence term")?;
        self.terms.push(Term {
            var: x.0,
            l: a.clone(),
            r: a.clone(),
            c: coef,
            congruence: true,
        });
        Ok(self)
    }

    /// Add `coef`·(LᵀXR + RᵀXL) with L, R of size n × `dim`. With selection
    /// matrices this places a non-symmetric product such as P_jΛ in an
    /// off-diagonal block: L = \[0 I\], R = Λ·\[I 0\] gives \[0, ΛᵀP_j; P_jΛ, 0\].
    pub fn sym_product(
        &mut self,
        x: LmiVar,
        l: &DMatrix<f64>,
        r: &DMatrix<f64>,
        coef: f64,
    ) -> Result<&mut Self, LmiError> {
        self.check_coef(coef)?;
        self.check_cols(l, "L of a product term")?;
        self.check_cols(r, "R of a product term")?;
        if l.nrows() != r.nrows() {
            return Err(LmiError::Dimension {
                context: format!("product term of constraint `{}`", self.name),
                problem: format!("L has {} rows, R has {}", l.nrows(), r.nrows()),
            });
        }
        // Internally c/2·(LᵀXR + RᵀXL).
        self.terms.push(Term {
            var: x.0,
            l: l.clone(),
            r: r.clone(),
            c: 2.0 * coef,
            congruence: false,
        });
        Ok(self)
    }

    fn check_cols(&self, m: &DMatrix<f64>, what: &str) -> Result<(), LmiError> {
        if m.ncols() != self.dim {
            return Err(LmiError::Dimension {
                context: format!("{what} of constraint `{}`", self.name),
                problem: format!("{} columns, expected {}", m.ncols(), self.dim),
            });
        }
        check_finite(m, || format!("{what} of constraint `{}`", self.name))
    }

    /// F(X) for the given variable values (sizes already checked).
    fn eval(&self, xs: &[DMatrix<f64>]) -> DMatrix<f64> {
        let mut f = self.constant.clone();
        for t in &self.terms {
            let x = &xs[t.var];
            if t.congruence {
                f += (t.l.transpose() * x * &t.l) * t.c;
            } else {
                let m = t.l.transpose() * x * &t.r;
                f += (&m + m.transpose()) * (0.5 * t.c);
            }
        }
        // Exactly symmetric.
        (&f + f.transpose()) * 0.5
    }
}

/// Options of [`LmiProblem::solve`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LmiOptions {
    /// R in −R·I ⪯ X_i ⪯ R·I (keeps phase I bounded). Irrelevant for homogeneous
    /// problems (no constants); otherwise the search is limited to ‖X_i‖₂ ≤ R.
    /// Default 1.
    pub bound: f64,
    /// Newton-step budget. Default 400.
    pub max_newton: usize,
    /// Stop when the duality gap ν/s of the normalised phase-I problem is below
    /// this (t* is then known to this accuracy). Default 1e-9.
    pub gap_tol: f64,
    /// Stop at the first verified feasible point (true, default) or maximise the
    /// normalised margin t (false) until it is known to 0.1 % (or the gap is below
    /// `gap_tol`).
    pub stop_at_first_feasible: bool,
    /// Refuse problems with more scalar unknowns (the Newton system is dense).
    /// Default 1500.
    pub max_unknowns: usize,
}

impl Default for LmiOptions {
    fn default() -> Self {
        Self {
            bound: 1.0,
            max_newton: 400,
            gap_tol: 1e-9,
            stop_at_first_feasible: true,
            max_unknowns: 1500,
        }
    }
}

/// Outcome of [`LmiProblem::solve`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LmiStatus {
    /// The returned variables satisfy every F_k(X) ≻ 0, verified by eigenvalues.
    Feasible,
    /// No X with ‖X_i‖ ≤ `bound` satisfies the LMIs: the upper bound on the
    /// phase-I optimum is < 0 (up to the centring accuracy of the barrier method).
    /// Only possible for problems with constant terms: for homogeneous ones X = 0
    /// gives t = 0, so t* ≥ 0 always (see `InfeasibleWithinTolerance`).
    Infeasible,
    /// The duality gap closed (below [`LmiOptions::gap_tol`]) without a verified
    /// certificate: no X with ‖X_i‖ ≤ `bound` reaches a normalised margin
    /// min_k λ_min(F_k/σ_k) above [`LmiSolution::t_upper`]. The LMIs are
    /// infeasible, or feasible only with a margin below the tolerance (a boundary
    /// case such as ρ(A) = 1 for a Lyapunov LMI). The usual "infeasible" answer
    /// for homogeneous problems.
    InfeasibleWithinTolerance,
    /// The Newton budget ran out (or the iteration broke down numerically)
    /// before either answer.
    Undecided,
}

impl fmt::Display for LmiStatus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            LmiStatus::Feasible => "feasible",
            LmiStatus::Infeasible => "infeasible",
            LmiStatus::InfeasibleWithinTolerance => "infeasible within tolerance",
            LmiStatus::Undecided => "undecided",
        })
    }
}

/// Result of [`LmiProblem::solve`].
#[derive(Debug, Clone)]
pub struct LmiSolution {
    /// The verdict.
    pub status: LmiStatus,
    /// The best X_i found (in declaration order); a certificate when `Feasible`.
    pub variables: Vec<DMatrix<f64>>,
    /// min_k λ_min(F_k(X)) of `variables`, recomputed from the data by eigenvalues
    /// (unscaled; > 0 when `Feasible`).
    pub margin: f64,
    /// λ_min(F_k(X)) per constraint, in the order they were added.
    pub min_eigs: Vec<f64>,
    /// The best phase-I value t on the normalised constraints (F_k/σ_k − t·I ⪰ 0).
    pub t: f64,
    /// Upper bound t + ν/s on the normalised phase-I optimum from the last
    /// centred point (+∞ if no centring finished).
    pub t_upper: f64,
    /// Newton steps taken.
    pub newton_steps: usize,
    /// Barrier parameters used (centring rounds).
    pub rounds: usize,
}

/// A set of symmetric matrix variables and strict LMIs in them (see the
/// [module docs](self)).
#[derive(Debug, Clone, Default)]
pub struct LmiProblem {
    vars: Vec<(String, usize)>,
    constraints: Vec<LmiConstraint>,
}

/// Basis of symmetric n×n matrices: (a, b), a ≤ b, E_aa = e_a e_aᵀ,
/// E_ab = e_a e_bᵀ + e_b e_aᵀ, so X_ab = x_j.
fn basis(n: usize) -> Vec<(usize, usize)> {
    let mut v = Vec::with_capacity(n * (n + 1) / 2);
    for a in 0..n {
        for b in a..n {
            v.push((a, b));
        }
    }
    v
}

/// tr(E_j M) for the symmetric basis element j = (a, b).
#[inline]
fn tr_e(m: &DMatrix<f64>, (a, b): (usize, usize)) -> f64 {
    if a == b {
        m[(a, a)]
    } else {
        m[(a, b)] + m[(b, a)]
    }
}

/// tr(E_j X E_l Yᵀ) = Σ_{(p,q)∈E_j} Σ_{(r,s)∈E_l} X_qr Y_ps.
#[inline]
fn t_xy(x: &DMatrix<f64>, y: &DMatrix<f64>, (a, b): (usize, usize), (c, d): (usize, usize)) -> f64 {
    match (a == b, c == d) {
        (true, true) => x[(a, c)] * y[(a, c)],
        (true, false) => x[(a, c)] * y[(a, d)] + x[(a, d)] * y[(a, c)],
        (false, true) => x[(b, c)] * y[(a, c)] + x[(a, c)] * y[(b, c)],
        (false, false) => {
            x[(b, c)] * y[(a, d)]
                + x[(b, d)] * y[(a, c)]
                + x[(a, c)] * y[(b, d)]
                + x[(a, d)] * y[(b, c)]
        }
    }
}

/// Log-determinant and inverse of a symmetric positive definite matrix, `None`
/// if it is not (numerically) positive definite.
fn logdet_inv(m: DMatrix<f64>, want_inv: bool) -> Option<(f64, Option<DMatrix<f64>>)> {
    if !m.iter().all(|v| v.is_finite()) {
        return None;
    }
    let ch = m.cholesky()?;
    let l = ch.l_dirty();
    let mut ld = 0.0;
    for i in 0..l.nrows() {
        let d = l[(i, i)];
        if d <= 0.0 || !d.is_finite() {
            return None;
        }
        ld += d.ln();
    }
    let inv = if want_inv { Some(ch.inverse()) } else { None };
    Some((2.0 * ld, inv))
}

/// Smallest eigenvalue of a symmetric matrix (NaN-free: a non-finite matrix
/// gives −∞).
fn min_eig(m: &DMatrix<f64>) -> f64 {
    if m.nrows() == 0 {
        return f64::INFINITY;
    }
    if !m.iter().all(|v| v.is_finite()) {
        return f64::NEG_INFINITY;
    }
    let e = m.clone().symmetric_eigenvalues();
    let v = e.iter().copied().fold(f64::INFINITY, f64::min);
    if v.is_nan() { f64::NEG_INFINITY } else { v }
}

/// Internal scaled problem.
struct Scaled<'a> {
    p: &'a LmiProblem,
    /// Offset of each variable in x.
    off: Vec<usize>,
    bases: Vec<Vec<(usize, usize)>>,
    /// Normalisation σ_k of constraint k (F_k/σ_k is what the barrier sees).
    sigma: Vec<f64>,
    /// Scalar unknowns (x has m entries, z = (x, t) has m + 1).
    m: usize,
    /// R of the box −R·I ⪯ X_i ⪯ R·I.
    bound: f64,
    /// Total size of all barrier matrices (duality gap ν/s).
    nu: f64,
}

impl<'a> Scaled<'a> {
    fn new(p: &'a LmiProblem, bound: f64) -> Self {
        let mut off = Vec::with_capacity(p.vars.len());
        let mut bases = Vec::with_capacity(p.vars.len());
        let mut m = 0;
        for (_, n) in &p.vars {
            off.push(m);
            let b = basis(*n);
            m += b.len();
            bases.push(b);
        }
        let sigma = p
            .constraints
            .iter()
            .map(|c| {
                let mut s = c.constant.norm();
                for t in &c.terms {
                    s += t.c.abs() * t.l.norm() * t.r.norm() * bound;
                }
                if s.is_finite() && s > 0.0 { s } else { 1.0 }
            })
            .collect();
        let nu = p.constraints.iter().map(|c| c.dim).sum::<usize>() as f64
            + 2.0 * p.vars.iter().map(|v| v.1).sum::<usize>() as f64;
        Self {
            p,
            off,
            bases,
            sigma,
            m,
            bound,
            nu,
        }
    }

    fn unpack(&self, z: &DVector<f64>) -> Vec<DMatrix<f64>> {
        self.p
            .vars
            .iter()
            .enumerate()
            .map(|(v, (_, n))| {
                let mut x = DMatrix::zeros(*n, *n);
                for (j, &(a, b)) in self.bases[v].iter().enumerate() {
                    let val = z[self.off[v] + j];
                    x[(a, b)] = val;
                    x[(b, a)] = val;
                }
                x
            })
            .collect()
    }

    /// The barrier matrices at z: scaled F_k − tI, then R·I − X_i, R·I + X_i.
    fn matrices(&self, z: &DVector<f64>) -> (Vec<DMatrix<f64>>, Vec<DMatrix<f64>>) {
        let xs = self.unpack(z);
        let t = z[self.m];
        let fs = self
            .p
            .constraints
            .iter()
            .zip(&self.sigma)
            .map(|(c, s)| {
                let mut f = c.eval(&xs) / *s;
                for i in 0..c.dim {
                    f[(i, i)] -= t;
                }
                f
            })
            .collect();
        let mut boxes = Vec::with_capacity(2 * xs.len());
        for x in &xs {
            let n = x.nrows();
            let ri = DMatrix::<f64>::identity(n, n) * self.bound;
            boxes.push(&ri - x);
            boxes.push(&ri + x);
        }
        (fs, boxes)
    }

    /// Barrier objective −s·t − Σ log det, `None` outside the domain.
    fn objective(&self, z: &DVector<f64>, s: f64) -> Option<f64> {
        let (fs, boxes) = self.matrices(z);
        let mut f = -s * z[self.m];
        for m in fs.into_iter().chain(boxes) {
            f -= logdet_inv(m, false)?.0;
        }
        f.is_finite().then_some(f)
    }

    /// Gradient and Hessian of the barrier objective at z (inside the domain).
    fn grad_hess(&self, z: &DVector<f64>, s: f64) -> Option<(DVector<f64>, DMatrix<f64>)> {
        let nz = self.m + 1;
        let it = self.m;
        let mut g = DVector::<f64>::zeros(nz);
        let mut h = DMatrix::<f64>::zeros(nz, nz);
        g[it] = -s;
        let (fs, boxes) = self.matrices(z);
        for ((c, fk), sig) in self.p.constraints.iter().zip(fs).zip(&self.sigma) {
            let (_, w) = logdet_inv(fk, true)?;
            let w = w?;
            let w2 = &w * &w;
            // t: ∂F/∂t = −I.
            g[it] += w.trace();
            h[(it, it)] += w2.trace();
            // Per term: gradient −c tr(E R W Lᵀ); cross with t: −c tr(E R W² Lᵀ).
            let lw: Vec<DMatrix<f64>> = c.terms.iter().map(|t| &t.l * &w).collect();
            let rw: Vec<DMatrix<f64>> = c
                .terms
                .iter()
                .map(|t| {
                    if t.congruence {
                        DMatrix::zeros(0, 0)
                    } else {
                        &t.r * &w
                    }
                })
                .collect();
            for (si, t) in c.terms.iter().enumerate() {
                let cs = t.c / sig;
                let rws = if t.congruence { &lw[si] } else { &rw[si] };
                let g1 = rws * t.l.transpose();
                let g2 = rws * &w * t.l.transpose();
                let o = self.off[t.var];
                for (j, &e) in self.bases[t.var].iter().enumerate() {
                    g[o + j] -= cs * tr_e(&g1, e);
                    let v = -cs * tr_e(&g2, e);
                    h[(o + j, it)] += v;
                    h[(it, o + j)] += v;
                }
            }
            // Pairs of terms.
            for (si, ts) in c.terms.iter().enumerate() {
                let cs = ts.c / sig;
                let os = self.off[ts.var];
                let rws = if ts.congruence { &lw[si] } else { &rw[si] };
                for tr in c.terms.iter() {
                    let cr = tr.c / sig;
                    let or = self.off[tr.var];
                    if ts.congruence && tr.congruence {
                        // c_s c_r tr(E G E' Gᵀ), G = A_s W A_rᵀ.
                        let gm = &lw[si] * tr.l.transpose();
                        let k = cs * cr;
                        for (j, &e) in self.bases[ts.var].iter().enumerate() {
                            for (l, &e2) in self.bases[tr.var].iter().enumerate() {
                                h[(os + j, or + l)] += k * t_xy(&gm, &gm, e, e2);
                            }
                        }
                    } else {
                        // c_s c_r/2 [T(P1, P4) + T(P2, P3)], P1 = R_s W L_rᵀ,
                        // P2 = R_s W R_rᵀ, P3 = L_s W L_rᵀ, P4 = L_s W R_rᵀ.
                        let p1 = rws * tr.l.transpose();
                        let p2 = rws * tr.r.transpose();
                        let p3 = &lw[si] * tr.l.transpose();
                        let p4 = &lw[si] * tr.r.transpose();
                        let k = 0.5 * cs * cr;
                        for (j, &e) in self.bases[ts.var].iter().enumerate() {
                            for (l, &e2) in self.bases[tr.var].iter().enumerate() {
                                h[(os + j, or + l)] +=
                                    k * (t_xy(&p1, &p4, e, e2) + t_xy(&p2, &p3, e, e2));
                            }
                        }
                    }
                }
            }
        }
        // Box constraints R·I ∓ X ⪰ 0: ∂ = ∓E.
        for (v, pair) in boxes.chunks(2).enumerate() {
            let o = self.off[v];
            for (sign, bm) in [(1.0, &pair[0]), (-1.0, &pair[1])] {
                let (_, w) = logdet_inv(bm.clone(), true)?;
                let w = w?;
                for (j, &e) in self.bases[v].iter().enumerate() {
                    g[o + j] += sign * tr_e(&w, e);
                    for (l, &e2) in self.bases[v].iter().enumerate() {
                        h[(o + j, o + l)] += t_xy(&w, &w, e, e2);
                    }
                }
            }
        }
        let ok = g.iter().all(|v| v.is_finite()) && h.iter().all(|v| v.is_finite());
        ok.then_some((g, h))
    }
}

/// Solve H Δ = −g by Cholesky, regularising H if it is numerically indefinite.
fn newton_direction(h: &DMatrix<f64>, g: &DVector<f64>) -> Option<DVector<f64>> {
    let scale = (0..h.nrows()).map(|i| h[(i, i)].abs()).fold(0.0, f64::max);
    let mut reg = 0.0;
    for _ in 0..8 {
        let mut hh = h.clone();
        for i in 0..hh.nrows() {
            hh[(i, i)] += reg;
        }
        if let Some(ch) = hh.cholesky() {
            let d = ch.solve(&(-g));
            if d.iter().all(|v| v.is_finite()) {
                return Some(d);
            }
        }
        reg = if reg == 0.0 {
            1e-12 * scale.max(1e-300)
        } else {
            reg * 100.0
        };
    }
    None
}

impl LmiProblem {
    /// An empty problem.
    pub fn new() -> Self {
        Self::default()
    }

    /// Declare a symmetric `n` × `n` matrix variable.
    pub fn variable(&mut self, name: impl Into<String>, n: usize) -> Result<LmiVar, LmiError> {
        let name = name.into();
        if n == 0 {
            return Err(LmiError::Empty(format!("variable `{name}` has size 0")));
        }
        self.vars.push((name, n));
        Ok(LmiVar(self.vars.len() - 1))
    }

    /// Add a constraint F ≻ 0; checks every term against its variable's size.
    /// Returns the constraint's index.
    pub fn add(&mut self, c: LmiConstraint) -> Result<usize, LmiError> {
        if c.dim == 0 {
            return Err(LmiError::Empty(format!(
                "constraint `{}` has size 0",
                c.name
            )));
        }
        c.check_size()?;
        for t in &c.terms {
            let Some((vname, n)) = self.vars.get(t.var) else {
                return Err(LmiError::UnknownVariable(t.var));
            };
            let rows = if t.l.nrows() != *n {
                t.l.nrows()
            } else {
                t.r.nrows()
            };
            if rows != *n {
                return Err(LmiError::Dimension {
                    context: format!("term in `{vname}` of constraint `{}`", c.name),
                    problem: format!("matrix has {rows} rows, `{vname}` is {n}×{n}"),
                });
            }
        }
        self.constraints.push(c);
        Ok(self.constraints.len() - 1)
    }

    /// Number of scalar unknowns Σ n_i(n_i + 1)/2.
    pub fn unknowns(&self) -> usize {
        self.vars.iter().fold(0usize, |acc, (_, n)| {
            acc.saturating_add(n.saturating_mul(n.saturating_add(1)) / 2)
        })
    }

    /// Number of variables.
    pub fn n_variables(&self) -> usize {
        self.vars.len()
    }

    /// Number of constraints.
    pub fn n_constraints(&self) -> usize {
        self.constraints.len()
    }

    /// Names of the constraints, in order.
    pub fn constraint_names(&self) -> Vec<&str> {
        self.constraints.iter().map(|c| c.name()).collect()
    }

    fn check_values(&self, xs: &[DMatrix<f64>]) -> Result<(), LmiError> {
        if xs.len() != self.vars.len() {
            return Err(LmiError::Dimension {
                context: "variable values".into(),
                problem: format!("{} matrices, expected {}", xs.len(), self.vars.len()),
            });
        }
        for ((name, n), x) in self.vars.iter().zip(xs) {
            if x.nrows() != *n || x.ncols() != *n {
                return Err(LmiError::Dimension {
                    context: format!("value of `{name}`"),
                    problem: format!("{}×{}, expected {n}×{n}", x.nrows(), x.ncols()),
                });
            }
            check_finite(x, || format!("value of `{name}`"))?;
        }
        Ok(())
    }

    /// F_k(X) of constraint `k` for variable values `xs` (symmetrised).
    pub fn evaluate(&self, k: usize, xs: &[DMatrix<f64>]) -> Result<DMatrix<f64>, LmiError> {
        self.check_values(xs)?;
        let c = self.constraints.get(k).ok_or_else(|| LmiError::Dimension {
            context: "constraint index".into(),
            problem: format!("{k} ≥ {} constraints", self.constraints.len()),
        })?;
        let sym: Vec<DMatrix<f64>> = xs.iter().map(|x| (x + x.transpose()) * 0.5).collect();
        Ok(c.eval(&sym))
    }

    /// λ_min(F_k(X)) for every constraint (symmetric eigen-decomposition): the
    /// independent check of a certificate.
    pub fn min_eigenvalues(&self, xs: &[DMatrix<f64>]) -> Result<Vec<f64>, LmiError> {
        (0..self.constraints.len())
            .map(|k| self.evaluate(k, xs).map(|f| min_eig(&f)))
            .collect()
    }

    /// Round-off threshold for constraint k: λ_min must exceed this to count as
    /// ≻ 0 (a multiple of ε times the size of the terms at X).
    fn threshold(&self, k: usize, xs: &[DMatrix<f64>]) -> f64 {
        let c = &self.constraints[k];
        let mut s = c.constant.norm();
        for t in &c.terms {
            s += t.c.abs() * t.l.norm() * t.r.norm() * xs[t.var].norm();
        }
        1e3 * f64::EPSILON * (c.dim as f64) * s.max(f64::MIN_POSITIVE)
    }

    /// Verify values: (all λ_min above threshold, min_eigs).
    fn certify(&self, xs: &[DMatrix<f64>]) -> (bool, Vec<f64>) {
        let eigs: Vec<f64> = (0..self.constraints.len())
            .map(|k| min_eig(&self.constraints[k].eval(xs)))
            .collect();
        let ok = eigs
            .iter()
            .enumerate()
            .all(|(k, &e)| e > self.threshold(k, xs));
        (ok, eigs)
    }

    /// Solve the feasibility problem (see the [module docs](self) for the method
    /// and the meaning of the verdicts). Never panics; errors only for empty or
    /// too large problems and bad options.
    pub fn solve(&self, opts: &LmiOptions) -> Result<LmiSolution, LmiError> {
        if !(opts.bound.is_finite() && opts.bound > 0.0) {
            return Err(LmiError::Option {
                name: "bound",
                problem: format!("{} (must be finite and > 0)", opts.bound),
            });
        }
        if !(opts.gap_tol.is_finite() && opts.gap_tol > 0.0) {
            return Err(LmiError::Option {
                name: "gap_tol",
                problem: format!("{} (must be finite and > 0)", opts.gap_tol),
            });
        }
        if self.vars.is_empty() {
            return Err(LmiError::Empty("no variables".into()));
        }
        if self.constraints.is_empty() {
            return Err(LmiError::Empty("no constraints".into()));
        }
        let unknowns = self.unknowns();
        if unknowns > opts.max_unknowns {
            return Err(LmiError::TooLarge {
                unknowns,
                limit: opts.max_unknowns,
            });
        }
        let sc = Scaled::new(self, opts.bound);
        let m = sc.m;
        // Start: X = 0, t below every scaled constant's smallest eigenvalue.
        let mut z = DVector::zeros(m + 1);
        let t0 = self
            .constraints
            .iter()
            .zip(&sc.sigma)
            .map(|(c, s)| min_eig(&(&c.constant / *s)))
            .fold(f64::INFINITY, f64::min);
        z[m] = if t0.is_finite() { t0 - 1.0 } else { -1.0 };
        let mut s = sc.nu.max(1.0);
        let mu = 10.0;
        let mut steps = 0usize;
        let mut rounds = 0usize;
        let mut t_upper = f64::INFINITY;
        let mut feasible: Option<(Vec<DMatrix<f64>>, Vec<f64>)> = None;
        let mut status = LmiStatus::Undecided;
        'outer: loop {
            rounds += 1;
            // Centring by damped Newton.
            let mut centred = false;
            while steps < opts.max_newton {
                let Some((g, h)) = sc.grad_hess(&z, s) else {
                    break 'outer;
                };
                let Some(dz) = newton_direction(&h, &g) else {
                    break 'outer;
                };
                let lambda2 = -g.dot(&dz);
                if !lambda2.is_finite() {
                    break 'outer;
                }
                if lambda2 <= 1e-9 {
                    centred = true;
                    break;
                }
                let Some(f0) = sc.objective(&z, s) else {
                    break 'outer;
                };
                let mut alpha = 1.0;
                let mut accepted = None;
                for _ in 0..60 {
                    let zn = &z + &dz * alpha;
                    if let Some(f1) = sc.objective(&zn, s)
                        && f1 <= f0 - 0.25 * alpha * lambda2
                    {
                        accepted = Some(zn);
                        break;
                    }
                    alpha *= 0.5;
                }
                steps += 1;
                let Some(zn) = accepted else {
                    // No decrease possible at machine precision: as centred as
                    // this point can be.
                    centred = true;
                    break;
                };
                z = zn;
                if alpha < 1e-6 && lambda2 < 1e-6 {
                    // Round-off limited (accepted only by rounding): stop centring.
                    centred = true;
                    break;
                }
                if z[m] > 0.0 {
                    let xs = sc.unpack(&z);
                    let (ok, eigs) = self.certify(&xs);
                    if ok {
                        feasible = Some((xs, eigs));
                        if opts.stop_at_first_feasible {
                            status = LmiStatus::Feasible;
                            break 'outer;
                        }
                    }
                }
            }
            if !centred {
                break; // Newton budget exhausted.
            }
            let gap = sc.nu / s;
            t_upper = z[m] + gap;
            if t_upper < 0.0 {
                status = LmiStatus::Infeasible;
                break;
            }
            if feasible.is_some() && gap <= 1e-3 * z[m] {
                break; // margin known to 0.1 %
            }
            if gap < opts.gap_tol {
                status = LmiStatus::InfeasibleWithinTolerance;
                break;
            }
            s *= mu;
        }
        if feasible.is_some() {
            status = LmiStatus::Feasible;
        }
        let t = z[m];
        let (variables, min_eigs) = match feasible {
            Some((xs, eigs)) => (xs, eigs),
            None => {
                let xs = sc.unpack(&z);
                let eigs = (0..self.constraints.len())
                    .map(|k| min_eig(&self.constraints[k].eval(&xs)))
                    .collect();
                (xs, eigs)
            }
        };
        // The last iterate may be better than the first verified one.
        let (variables, min_eigs) = if status == LmiStatus::Feasible && !opts.stop_at_first_feasible
        {
            let xs = sc.unpack(&z);
            let (ok, eigs) = self.certify(&xs);
            if ok {
                (xs, eigs)
            } else {
                (variables, min_eigs)
            }
        } else {
            (variables, min_eigs)
        };
        let margin = min_eigs.iter().copied().fold(f64::INFINITY, f64::min);
        Ok(LmiSolution {
            status,
            variables,
            margin: if margin.is_nan() {
                f64::NEG_INFINITY
            } else {
                margin
            },
            min_eigs,
            t: if t.is_finite() { t } else { f64::NEG_INFINITY },
            t_upper,
            newton_steps: steps,
            rounds,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The analytic gradient and Hessian of the barrier objective equal central
    /// finite differences (congruence, plain and product terms, two variables).
    #[test]
    fn gradient_and_hessian_match_finite_differences() {
        let mut rng = crate::rng::Rng::new(11);
        let mut m = |r: usize, c: usize| DMatrix::from_fn(r, c, |_, _| rng.uniform_in(-1.0, 1.0));
        let mut p = LmiProblem::new();
        let x = p.variable("X", 2).unwrap();
        let y = p.variable("Y", 3).unwrap();
        let mut c1 = LmiConstraint::new("c1", 3);
        c1.identity(2.0)
            .unwrap()
            .congruence(x, &m(2, 3), 0.7)
            .unwrap()
            .sym_product(y, &m(3, 3), &m(3, 3), -0.4)
            .unwrap()
            .var(y, 0.3)
            .unwrap();
        p.add(c1).unwrap();
        let mut c2 = LmiConstraint::new("c2", 4);
        c2.identity(1.5)
            .unwrap()
            .sym_product(x, &m(2, 4), &m(2, 4), 0.5)
            .unwrap()
            .congruence(y, &m(3, 4), -0.6)
            .unwrap();
        p.add(c2).unwrap();
        let sc = Scaled::new(&p, 1.0);
        let n = sc.m + 1;
        let mut z = DVector::from_fn(n, |_, _| 0.0);
        for i in 0..sc.m {
            z[i] = 0.1 * ((i as f64) * 0.7).sin();
        }
        z[sc.m] = -0.5;
        let s = 3.0;
        let (g, h) = sc.grad_hess(&z, s).unwrap();
        let eps = 1e-5;
        for i in 0..n {
            let mut zp = z.clone();
            let mut zm = z.clone();
            zp[i] += eps;
            zm[i] -= eps;
            let fd = (sc.objective(&zp, s).unwrap() - sc.objective(&zm, s).unwrap()) / (2.0 * eps);
            assert!(
                (fd - g[i]).abs() < 1e-6 * (1.0 + g[i].abs()),
                "g[{i}]: {fd} vs {}",
                g[i]
            );
            let gp = sc.grad_hess(&zp, s).unwrap().0;
            let gm = sc.grad_hess(&zm, s).unwrap().0;
            for j in 0..n {
                let fd = (gp[j] - gm[j]) / (2.0 * eps);
                assert!(
                    (fd - h[(j, i)]).abs() < 1e-5 * (1.0 + h[(j, i)].abs()),
                    "H[{j},{i}]: {fd} vs {}",
                    h[(j, i)]
                );
            }
        }
        assert!((&h - h.transpose()).amax() < 1e-12 * h.amax());
    }
}

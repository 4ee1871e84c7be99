//! `prandtl_ishlinskii`: the Prandtl–Ishlinskii hysteresis operator, the third
//! model of the `hysteresis` vocabulary entry. Coleman–Hodgdon (`hysteresis`) is
//! the thesis's piezo model (Sec. 6.3) and Bouc–Wen (`bouc_wen`) the model of
//! hysteretic restoring forces; Prandtl–Ishlinskii is the standard
//! phenomenological model of piezo and magnetostrictive actuators in the
//! precision-positioning literature: a weighted sum of play operators, so its
//! loops take any shape a superposition of plays can (a Preisach map restricted
//! to symmetric relays), its parameters enter linearly (a fit is a least-squares
//! problem), and its inverse is again a Prandtl–Ishlinskii operator
//! ([`PrandtlIshlinskii::inverse`]) — the feed-forward compensator of Ch. 6
//! without an iteration.

use super::{MAX_MAGNITUDE, check_bounded, check_len};
use nanomotion_core::Params;
use nanomotion_core::block::check;
use nanomotion_core::{Block, BuildContext, ParamError, Sector, Tick, Tunable, declared_block};
use serde::{Deserialize, Serialize};

/// Most plays a `prandtl_ishlinskii` block may have.
pub const MAX_PLAYS: usize = 16;

/// The least slope of an actuator material's hysteresis branch, as a share of
/// its steepest (see [`PrandtlIshlinskii::implausible`]): half the thesis's
/// piezo (0.4).
pub const MIN_SLOPE_SHARE: f64 = 0.2;

/// One play operator of [`PrandtlIshlinskii`]: its radius (half its width) and
/// its weight in the sum.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
pub struct Play {
    /// Radius r_i (unit of u) ≥ 0: the play's output moves once the input is
    /// r_i past it.
    pub radius: f64,
    /// Weight w_i (\[y\]/\[u\]).
    pub weight: f64,
}

/// `prandtl_ishlinskii`: PLF effect (hysteresis): y = linear·u + Σ w_i·F_{r_i}(u), F_r
/// the play operator of radius r (radii increasing), started at the first input;
/// tunable [linear, ratio_1, ...]: each play's factor on the branch's slope.
///
/// ```text
/// F_r(u)_k = min(u_k + r, max(u_k − r, F_r(u)_{k−1})),   F_r(u)_0 = u_0
/// y_k      = linear·u_k + Σ_i w_i·F_{r_i}(u)_k
/// ```
///
/// Every play starts at the first finite input (the actuator at rest there); a
/// non-finite input passes through without changing the plays. Right after a
/// reversal every play of radius > 0 holds and the branch's slope is a₀ =
/// `linear`; once the input has travelled 2·r_j back, play j moves with it
/// and the slope becomes a_j = a_{j−1} + w_j (the loading curve's slopes,
/// [`PrandtlIshlinskii::branch_slopes`]). Every branch is strictly increasing
/// exactly when every a_j > 0 — an actuator material's hysteresis — and then
/// the operator has a Prandtl–Ishlinskii inverse
/// ([`PrandtlIshlinskii::inverse`]). Weights may be negative (a loop that
/// saturates) as long as the slopes stay positive.
///
/// Slope range ([`Block::sector`]): [min_j a_j, max_j a_j]. The plays start
/// together, so |F_r − F_r'| ≤ |r − r'| at every sample; a play pushed by the
/// input therefore has every narrower play pushed with it, and the plays that
/// move are always the narrowest ones. Along a sample's chord the slope is
/// thus one of the a_j at every point, and Δy/Δu, their average, lies
/// between the smallest and the largest.
///
/// [`Tunable`] vector: `[linear, ratio_1, ratio_2, ...]`, ratio_j = a_j/a_{j−1}
/// the factor by which play j changes the branch's slope when it starts to
/// move (YAML `linear` and `plays[j].weight` = a_j − a_{j−1}). Every loop with
/// positive slopes has positive ratios, and ratios of 1 are a plain gain, so a
/// fit on a log scale stays physical and starts from the nominal. A ratio
/// after a slope of 0 is undefined (NaN): such an operator is not tuned by
/// ratios. The radii are the operator's structure, not fitted.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "prandtl_ishlinskii", role = Actuator, ports = "u -> y")]
pub struct PrandtlIshlinskii {
    /// Linear part of the output (\[y\]/\[u\]): the slope a₀ right after a
    /// reversal.
    pub linear: f64,
    /// The plays {radius, weight}, radii increasing.
    /// [{radius: r_j ≥ 0 (unit of u), weight: w_j (\[y\]/\[u\])}].
    #[param(len(1, MAX_PLAYS))]
    pub plays: Vec<Play>,
    /// Each play's output; meaningful once `started`.
    #[serde(skip)]
    state: [f64; MAX_PLAYS],
    #[serde(skip)]
    started: bool,
}

impl PrandtlIshlinskii {
    /// The operator linear·u + Σ w_i·F_{r_i}(u).
    pub fn new(linear: f64, plays: Vec<Play>) -> Self {
        Self {
            linear,
            plays,
            state: [0.0; MAX_PLAYS],
            started: false,
        }
    }

    /// The operator a block's JSON describes (as `surgery::block_to_json` or
    /// a report writes it, its `type` tag included), or `None` when the JSON is
    /// not one.
    pub fn from_block_json(block: &serde_json::Value) -> Option<Self> {
        let mut fields = block.clone();
        fields.as_object_mut()?.remove("type");
        serde_json::from_value(fields).ok()
    }

    fn check_values(linear: f64, plays: &[Play]) -> Result<(), ParamError> {
        check_bounded("linear", linear, MAX_MAGNITUDE)?;
        for (i, p) in plays.iter().enumerate() {
            let field = format!("plays[{i}].radius");
            check::non_negative(&field, p.radius)?;
            check_bounded(&field, p.radius, MAX_MAGNITUDE)?;
            if i > 0 && p.radius <= plays[i - 1].radius {
                return Err(ParamError::new(
                    field,
                    format!(
                        "is {}, not larger than plays[{}].radius = {}",
                        p.radius,
                        i - 1,
                        plays[i - 1].radius
                    ),
                    "list the plays by increasing radius, each radius once (merge equal radii by adding their weights)",
                ));
            }
            check_bounded(&format!("plays[{i}].weight"), p.weight, MAX_MAGNITUDE)?;
        }
        Ok(())
    }

    /// The slope range [min_j a_j, max_j a_j] of the branch slopes
    /// ([`PrandtlIshlinskii::branch_slopes`]): exact for every input sequence
    /// (see [`Block::sector`] on the block's doc).
    pub fn slope_range(&self) -> (f64, f64) {
        self.branch_slopes()
            .into_iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), a| {
                (lo.min(a), hi.max(a))
            })
    }

    /// The loading curve's slopes a₀ = linear, a_j = a_{j−1} + w_j: the
    /// branch's slope once the input has travelled 2·r_j from its last
    /// reversal (for j ≥ 1; a₀ right after it).
    pub fn branch_slopes(&self) -> Vec<f64> {
        std::iter::once(self.linear)
            .chain(self.plays.iter().scan(self.linear, |a, p| {
                *a += p.weight;
                Some(*a)
            }))
            .collect()
    }

    /// Why these parameters are not an actuator material's hysteresis, or
    /// `None`:
    /// - a branch that stops or turns back (a slope a_j ≤ 0, see
    ///   [`PrandtlIshlinskii::branch_slopes`]);
    /// - a branch that goes flat: a slope below [`MIN_SLOPE_SHARE`] of the
    ///   steepest — right after a reversal, a dead band (the play of a gear or
    ///   a joint: `backlash`); part-way along, a stall (a stage that sticks
    ///   until its drive overcomes friction). A material answers every move of
    ///   its drive: the thesis's piezo (Table 6.2) has slopes from 2c − b ≈
    ///   0.4 after a reversal to b ≈ 1 µm/V.
    pub fn implausible(&self) -> Option<String> {
        let slopes = self.branch_slopes();
        let travel = |j: usize| {
            if j == 0 {
                0.0
            } else {
                2.0 * self.plays[j - 1].radius
            }
        };
        if let Some(j) = slopes.iter().position(|&a| a.is_nan() || a <= 0.0) {
            return Some(format!(
                "its branches turn back: slope {:.3e} once the input has travelled {:.3e} from a reversal (a material's hysteresis is monotone on every branch)",
                slopes[j],
                travel(j)
            ));
        }
        let steepest = slopes.iter().copied().fold(0.0, f64::max);
        let j = slopes
            .iter()
            .position(|&a| a < MIN_SLOPE_SHARE * steepest)?;
        Some(format!(
            "its branches go flat: slope {:.3e} once the input has travelled {:.3e} from a reversal, {:.1} % of the steepest {steepest:.3e} (at least {:.0} %): {}, not a material's loop",
            slopes[j],
            travel(j),
            100.0 * slopes[j] / steepest,
            100.0 * MIN_SLOPE_SHARE,
            if j == 0 {
                "a dead band after each reversal (backlash)"
            } else {
                "a stall part-way along a branch (a stage that sticks)"
            }
        ))
    }

    /// The inverse operator: the Prandtl–Ishlinskii operator P⁻¹ with
    /// P⁻¹(P(u)) = u for every input sequence, both started at rest (P⁻¹ at
    /// P's first output, P at P⁻¹'s first output). Needs every branch slope
    /// a_j > 0 ([`PrandtlIshlinskii::branch_slopes`]).
    ///
    /// The loading curve of P is piecewise linear with knots at the radii r_j
    /// and slopes a_j. A Prandtl–Ishlinskii operator is fixed by its loading
    /// curve, and the operator of φ⁻¹ inverts the operator of φ (Brokate and
    /// Sprekels, *Hysteresis and Phase Transitions*, Sec. 2.3): φ⁻¹ is
    /// piecewise linear with knots at φ(r_j) and slopes 1/a_j, so P⁻¹ has
    /// plays of radius φ(r_j) = Σ_{i<j} a_i·(r_{i+1} − r_i) (r₀ := 0 before
    /// the first knot), weights 1/a_j − 1/a_{j−1}, and linear part 1/a₀.
    /// `None` when a slope is ≤ 0 (a branch stops or turns back: no inverse
    /// exists).
    pub fn inverse(&self) -> Option<PrandtlIshlinskii> {
        let slopes = self.branch_slopes();
        if slopes.iter().any(|&a| a.is_nan() || a <= 0.0) {
            return None;
        }
        let (mut phi, mut r_prev) = (0.0, 0.0);
        let plays = self
            .plays
            .iter()
            .enumerate()
            .map(|(j, p)| {
                phi += slopes[j] * (p.radius - r_prev);
                r_prev = p.radius;
                Play {
                    radius: phi,
                    weight: 1.0 / slopes[j + 1] - 1.0 / slopes[j],
                }
            })
            .collect();
        Some(PrandtlIshlinskii::new(1.0 / slopes[0], plays))
    }
}

#[declared_block]
impl Block for PrandtlIshlinskii {
    fn build(&mut self, _ctx: &BuildContext) -> Result<(), ParamError> {
        self.check_params()?;
        Self::check_values(self.linear, &self.plays)?;
        self.state = [0.0; MAX_PLAYS];
        self.started = false;
        Ok(())
    }
    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        let u = u[0];
        if !u.is_finite() {
            y[0] = u;
            return;
        }
        let n = self.plays.len().min(MAX_PLAYS);
        if !self.started {
            self.state[..n].iter_mut().for_each(|s| *s = u);
            self.started = true;
        }
        let mut out = self.linear * u;
        for (s, p) in self.state[..n].iter_mut().zip(&self.plays) {
            *s = s.clamp(u - p.radius, u + p.radius);
            out += p.weight * *s;
        }
        y[0] = out;
    }
    fn sector(&self) -> Option<Sector> {
        let (lower, upper) = self.slope_range();
        (lower.is_finite() && upper.is_finite()).then(|| {
            Sector::new(
                lower,
                upper,
                "Prandtl–Ishlinskii: the branch slopes a_j (the narrowest plays move)",
            )
        })
    }
    fn tunable(&self) -> Option<&dyn Tunable> {
        Some(self)
    }
    fn tunable_mut(&mut self) -> Option<&mut dyn Tunable> {
        Some(self)
    }
}

impl Tunable for PrandtlIshlinskii {
    fn param_names(&self) -> Vec<String> {
        std::iter::once("linear".to_string())
            .chain((0..self.plays.len()).map(|j| format!("plays[{j}].ratio")))
            .collect()
    }
    fn params(&self) -> Vec<f64> {
        let a = self.branch_slopes();
        std::iter::once(self.linear)
            .chain(
                a.windows(2)
                    .map(|w| if w[0] != 0.0 { w[1] / w[0] } else { f64::NAN }),
            )
            .collect()
    }
    fn set_params(&mut self, p: &[f64]) -> Result<(), ParamError> {
        check_len(p, 1 + self.plays.len(), "[linear, ratio_1, ratio_2, ...]")?;
        let mut next = self.plays.clone();
        let mut slope = p[0];
        for (play, &ratio) in next.iter_mut().zip(&p[1..]) {
            play.weight = slope * (ratio - 1.0);
            slope *= ratio;
        }
        Self::check_values(p[0], &next)?;
        self.linear = p[0];
        self.plays = next;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(b: &mut PrandtlIshlinskii, u: &[f64]) -> Vec<f64> {
        b.build(&BuildContext::new("pi", 1e-3, 0)).unwrap();
        u.iter()
            .enumerate()
            .map(|(k, &x)| {
                let mut y = [0.0];
                b.output(Tick::new(k as u64, 1e-3), &[x], &mut y);
                y[0]
            })
            .collect()
    }

    /// The largest |a_k − b_k|.
    fn max_gap(a: &[f64], b: &[f64]) -> f64 {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max)
    }

    /// A damped, offset sine: reversals of every amplitude, so every play
    /// takes part.
    fn sweep(n: usize) -> Vec<f64> {
        (0..n)
            .map(|k| {
                let t = k as f64 / n as f64;
                0.3 + (1.0 - 0.8 * t) * (40.0 * t).sin() + 0.2 * (97.0 * t).sin()
            })
            .collect()
    }

    /// One play of weight 1 and no linear part is the backlash of width 2r,
    /// sample for sample (an independent implementation, `Backlash`).
    #[test]
    fn one_play_is_the_backlash_of_twice_its_radius() {
        let u = sweep(2000);
        let mut pi = PrandtlIshlinskii::new(
            0.0,
            vec![Play {
                radius: 0.25,
                weight: 1.0,
            }],
        );
        let mut bl = super::super::Backlash::new(0.5);
        bl.build(&BuildContext::new("bl", 1e-3, 0)).unwrap();
        let y = run(&mut pi, &u);
        for (k, (&x, &yk)) in u.iter().zip(&y).enumerate() {
            let mut b = [0.0];
            bl.output(Tick::new(k as u64, 1e-3), &[x], &mut b);
            assert!((yk - b[0]).abs() < 1e-15, "sample {k}: {yk} vs {}", b[0]);
        }
    }

    /// The inverse undoes the operator: P⁻¹(P(u)) = u and P(P⁻¹(v)) = v to
    /// round-off on a sequence with reversals of every size, and the inverse's
    /// loading curve is the reflection of P's (closed form at each knot).
    #[test]
    fn the_inverse_undoes_the_operator_both_ways() {
        let plays: Vec<Play> = [(0.0, 0.1), (0.1, 0.4), (0.3, 0.25), (0.6, 0.5)]
            .iter()
            .map(|&(radius, weight)| Play { radius, weight })
            .collect();
        let mut p = PrandtlIshlinskii::new(0.7, plays);
        let mut inv = p.inverse().unwrap();
        let u = sweep(3000);
        let y = run(&mut p, &u);
        let back = run(&mut inv, &y);
        let worst = max_gap(u.as_slice(), &back);
        assert!(worst < 1e-12, "P⁻¹(P(u)) off by {worst:e}");
        let v = run(&mut inv, &u);
        let forth = run(&mut p, &v);
        let worst = max_gap(u.as_slice(), &forth);
        assert!(worst < 1e-12, "P(P⁻¹(v)) off by {worst:e}");
        // The inverse's slope range: from 1/(0.7 + 0.1 + 0.4 + 0.25 + 0.5),
        // every play moving, to 1/a₀ = 1/0.7.
        let (lo, hi) = inv.slope_range();
        assert!((hi - 1.0 / 0.7).abs() < 1e-12, "{hi}");
        assert!((lo - 1.0 / 1.95).abs() < 1e-12, "{lo}");
        // No inverse where a branch can stop or turn back.
        assert!(
            PrandtlIshlinskii::new(
                0.0,
                vec![Play {
                    radius: 0.1,
                    weight: 1.0
                }]
            )
            .inverse()
            .is_none()
        );
        let turning = vec![Play {
            radius: 0.1,
            weight: -1.2,
        }];
        let turning = PrandtlIshlinskii::new(1.0, turning);
        assert!(turning.inverse().is_none() && turning.implausible().is_some());
        // A dead band after each reversal (backlash's play): invertible
        // nowhere near, and not a material's loop.
        let flat = PrandtlIshlinskii::new(
            0.05,
            vec![Play {
                radius: 0.1,
                weight: 0.95,
            }],
        );
        assert!(flat.implausible().unwrap().contains("dead band"));
        // A stall part-way: slopes 1, 1, 0.05, 1.
        let stall = vec![
            Play {
                radius: 0.05,
                weight: 0.0,
            },
            Play {
                radius: 0.1,
                weight: -0.95,
            },
            Play {
                radius: 0.2,
                weight: 0.95,
            },
        ];
        let stall = PrandtlIshlinskii::new(1.0, stall).implausible().unwrap();
        assert!(
            stall.contains("stall") && stall.contains("2.000e-1"),
            "{stall}"
        );
        let mut p4 = PrandtlIshlinskii::new(
            0.7,
            vec![Play {
                radius: 0.1,
                weight: 0.4,
            }],
        );
        assert!(p4.implausible().is_none());
        p4.linear = 0.2;
        assert!(p4.implausible().is_none(), "0.2 of 0.6 is a third");
        // A saturating loop (a negative weight, every slope still positive)
        // is invertible too.
        let saturating = vec![
            Play {
                radius: 0.05,
                weight: -0.3,
            },
            Play {
                radius: 0.4,
                weight: -0.4,
            },
        ];
        let mut p = PrandtlIshlinskii::new(1.0, saturating);
        assert!(p.implausible().is_none());
        let mut inv = p.inverse().unwrap();
        let y = run(&mut p, &u);
        let back = run(&mut inv, &y);
        let worst = max_gap(u.as_slice(), &back);
        assert!(worst < 1e-12, "saturating: P⁻¹(P(u)) off by {worst:e}");
    }

    /// The declared slope range holds for every sample pair of the sweep, and
    /// both its ends are reached: `linear` right after a reversal (every play
    /// holds), linear + w₁ with the narrow play moving and the wide one not
    /// yet; with both moving the slope is 0.9, inside.
    #[test]
    fn the_slope_range_bounds_every_step() {
        let plays = vec![
            Play {
                radius: 0.05,
                weight: 0.5,
            },
            Play {
                radius: 0.2,
                weight: -0.2,
            },
        ];
        let mut p = PrandtlIshlinskii::new(0.6, plays);
        let (lo, hi) = p.slope_range();
        assert_eq!((lo, hi), (0.6, 0.6 + 0.5));
        let u = sweep(4000);
        let y = run(&mut p, &u);
        let (mut seen_lo, mut seen_hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for k in 1..u.len() {
            let du = u[k] - u[k - 1];
            if du.abs() > 1e-9 {
                let s = (y[k] - y[k - 1]) / du;
                assert!(s >= lo - 1e-9 && s <= hi + 1e-9, "slope {s} at {k}");
                seen_lo = seen_lo.min(s);
                seen_hi = seen_hi.max(s);
            }
        }
        assert!((seen_lo - 0.6).abs() < 1e-9, "after a reversal: {seen_lo}");
        assert!(
            (seen_hi - 1.1).abs() < 1e-9,
            "narrow play moving: {seen_hi}"
        );
    }

    #[test]
    fn bad_parameters_are_refused_by_name() {
        let mut p = PrandtlIshlinskii::new(
            1.0,
            vec![Play {
                radius: -0.1,
                weight: 0.2,
            }],
        );
        let e = p.build(&BuildContext::new("pi", 1e-3, 0)).unwrap_err();
        assert_eq!(e.field, "plays[0].radius");
        let mut p = PrandtlIshlinskii::new(
            f64::NAN,
            vec![Play {
                radius: 0.1,
                weight: 0.2,
            }],
        );
        assert_eq!(
            p.build(&BuildContext::new("pi", 1e-3, 0))
                .unwrap_err()
                .field,
            "linear"
        );
        let mut p = PrandtlIshlinskii::new(
            1.0,
            vec![Play {
                radius: 0.1,
                weight: 0.2,
            }],
        );
        assert!(p.set_params(&[1.0]).is_err());
        assert!(p.set_params(&[1.0, f64::INFINITY]).is_err());
        // Ratios: a₀ = 0.5, a₁ = 0.5·3 = 1.5, so w₁ = 1.0.
        p.set_params(&[0.5, 3.0]).unwrap();
        assert_eq!(p.plays[0].weight, 1.0);
        assert_eq!(p.params(), vec![0.5, 3.0]);
        let unsorted = vec![
            Play {
                radius: 0.2,
                weight: 0.1,
            },
            Play {
                radius: 0.1,
                weight: 0.1,
            },
        ];
        let e = PrandtlIshlinskii::new(1.0, unsorted)
            .build(&BuildContext::new("pi", 1e-3, 0))
            .unwrap_err();
        assert_eq!(e.field, "plays[1].radius");
    }
}

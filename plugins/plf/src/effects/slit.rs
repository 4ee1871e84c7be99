//! `encoder_slit_error`: per-slit line-position errors of an optical encoder.

use super::{MAX_MAGNITUDE, check_bounded, check_len};
use nanomotion_core::Params;
use nanomotion_core::{Block, BuildContext, ParamError, Tick, Tunable, declared_block};
use serde::{Deserialize, Serialize};

/// Longest error table of an `encoder_slit_error`.
pub const MAX_SLITS: usize = 4096;

/// `encoder_slit_error`: PLF effect: optical-encoder slit errors y = u + e[⌊(u −
/// origin)/pitch⌋ mod N] (Ch. 8–9); tunable [errors..].
///
/// Y = u + e[i mod N], i = ⌊(u − origin)/pitch⌋ the slit the
/// position u is on. The errors e_0..e_{N−1} are the deviations of the encoder's
/// line (slit) positions from the ideal grid, repeating every revolution of N slits
/// (Merry 2009, Ch. 8–9: the slit errors behind the time-stamping encoder's
/// position and velocity errors). A measured profile (e.g. a US Digital E2 disc)
/// is a smooth once- and twice-per-revolution shape plus slit-to-slit scatter of a
/// fraction of the pitch. 1 ≤ N ≤ [`MAX_SLITS`].
///
/// [`Tunable`] vector: `[errors[0..N]]`.
#[derive(Debug, Clone, Serialize, Deserialize, Params)]
#[serde(deny_unknown_fields)]
#[block(type_name = "encoder_slit_error", role = Sensor, ports = "u -> y")]
pub struct EncoderSlitError {
    /// Slit pitch (unit of u, e.g. m or rad).
    #[param(positive)]
    pub pitch: f64,
    /// Position of slit 0 (unit of u), default 0.
    #[serde(default)]
    pub origin: f64,
    /// e_0..e_{N−1} (unit of u): line-position errors.
    #[param(len(1, MAX_SLITS))]
    pub errors: Vec<f64>,
}

impl EncoderSlitError {
    /// A table of `errors` on slits of `pitch`, slit 0 at `origin`.
    pub fn new(pitch: f64, origin: f64, errors: Vec<f64>) -> Self {
        Self {
            pitch,
            origin,
            errors,
        }
    }

    /// The table index of the slit position `u` is on (0 for a non-finite u).
    pub fn slit(&self, u: f64) -> usize {
        let n = self.errors.len();
        let i = ((u - self.origin) / self.pitch).floor();
        if !i.is_finite() || n == 0 {
            return 0;
        }
        (i.rem_euclid(n as f64) as usize).min(n - 1)
    }

    /// The errors' magnitudes (their count is declared).
    fn check_errors(e: &[f64]) -> Result<(), ParamError> {
        for (i, v) in e.iter().enumerate() {
            check_bounded(&format!("errors[{i}]"), *v, MAX_MAGNITUDE)?;
        }
        Ok(())
    }
}

#[declared_block]
impl Block for EncoderSlitError {
    fn build(&mut self, _ctx: &BuildContext) -> Result<(), ParamError> {
        // pitch > 0 and 1 to 4096 errors: declared
        self.check_params()?;
        check_bounded("origin", self.origin, MAX_MAGNITUDE)?;
        Self::check_errors(&self.errors)
    }
    fn output(&mut self, _tick: Tick, u: &[f64], y: &mut [f64]) {
        let e = self.errors.get(self.slit(u[0])).copied().unwrap_or(0.0);
        y[0] = u[0] + e;
    }
    fn tunable(&self) -> Option<&dyn Tunable> {
        Some(self)
    }
    fn tunable_mut(&mut self) -> Option<&mut dyn Tunable> {
        Some(self)
    }
}

impl Tunable for EncoderSlitError {
    fn param_names(&self) -> Vec<String> {
        (0..self.errors.len())
            .map(|i| format!("errors[{i}]"))
            .collect()
    }
    fn params(&self) -> Vec<f64> {
        self.errors.clone()
    }
    fn set_params(&mut self, p: &[f64]) -> Result<(), ParamError> {
        check_len(p, self.errors.len(), "[errors[0..N]]")?;
        Self::check_errors(p)?;
        self.errors.copy_from_slice(p);
        Ok(())
    }
}

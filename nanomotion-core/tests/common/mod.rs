//! Shared by the derive tests: a test block's `Block` impl.

/// Implement `Block` for a `#[derive(Params)]` test struct registered as
/// `$name`: one input `u`, one output `y` = u, and a `build()` that checks
/// the declared bounds (`check_params`, then `check_at_rate` with the block's
/// period) — what a real block's `build()` starts with.
#[macro_export]
macro_rules! pass_through_block {
    ($t:ty, $name:literal) => {
        #[typetag::serde(name = $name)]
        impl nanomotion_core::Block for $t {
            fn inputs(&self) -> Vec<nanomotion_core::Port> {
                vec![nanomotion_core::Port::new("u", 1)]
            }
            fn outputs(&self) -> Vec<nanomotion_core::Port> {
                vec![nanomotion_core::Port::new("y", 1)]
            }
            fn build(
                &mut self,
                ctx: &nanomotion_core::BuildContext,
            ) -> Result<(), nanomotion_core::ParamError> {
                nanomotion_core::doc::Params::check_params(self)?;
                nanomotion_core::doc::Params::check_at_rate(self, ctx.dt)
            }
            fn output(&mut self, _t: nanomotion_core::Tick, u: &[f64], y: &mut [f64]) {
                y[0] = u[0];
            }
        }
    };
}

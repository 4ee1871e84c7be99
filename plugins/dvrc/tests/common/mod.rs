pub mod table51;
pub mod table51_nonlinear;

//! Set-up shared by the facade's integration tests.

use nanomotion::rt::RtConfig;

/// A real-time run that works on any machine: SCHED_FIFO 80 where permitted,
/// normal priority where not (`allow_soft`), memory unlocked, the CPUs' idle
/// states left alone, and late ticks caught up so that every tick runs
/// ([`RtConfig::soft_catch_up`]).
pub fn soft_catch_up() -> RtConfig {
    RtConfig::soft_catch_up()
}

//! Set-up shared by the facade's integration tests.

use nanomotion::rt::clock::Privileges;
use nanomotion::rt::{OverrunPolicy, RtConfig};

/// A real-time run that works on any machine: SCHED_FIFO 80 where permitted,
/// normal priority where not (`allow_soft`), memory unlocked, the CPUs' idle
/// states left alone, and late ticks caught up so that every tick runs.
pub fn soft_catch_up() -> RtConfig {
    RtConfig {
        privileges: Privileges {
            priority: Some(80),
            cpu: None,
            lock_memory: false,
            hold_cpu_latency: false,
        },
        allow_soft: true,
        overrun: OverrunPolicy::CatchUp,
        ..RtConfig::default()
    }
}

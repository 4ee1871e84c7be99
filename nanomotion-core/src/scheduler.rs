//! Scheduler (in progress).
pub struct Scheduler;

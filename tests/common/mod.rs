//! Set-up shared by the facade's integration tests (each test crate uses
//! some of it).
#![allow(dead_code)]

use nanomotion::rt::RtConfig;
use std::path::{Path, PathBuf};

/// A real-time run that works on any machine: SCHED_FIFO 80 where permitted,
/// normal priority where not (`allow_soft`), memory unlocked, the CPUs' idle
/// states left alone, and late ticks caught up so that every tick runs
/// ([`RtConfig::soft_catch_up`]).
pub fn soft_catch_up() -> RtConfig {
    RtConfig::soft_catch_up()
}

/// Run the `nanomotion` binary with `args` from the repository root: (success,
/// stdout, stderr).
pub fn cli(args: &[&str]) -> (bool, String, String) {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_nanomotion"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// A fresh folder `name` under the tests' temporary directory (removed if it
/// exists, not created).
pub fn scratch(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&d);
    d
}

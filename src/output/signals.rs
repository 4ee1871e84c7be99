//! Ctrl-C (SIGINT), SIGTERM and SIGHUP: the staging folders and locks of
//! [`super::OutputFolder`] and [`super::FolderLock`] are removed before the process ends.
//!
//! [`install`] (called by the `nanomotion` binary, not by the library) starts a
//! thread that waits for the signals (`signal-hook`). On a signal it raises the
//! flag that [`interrupted`] reads, which the writers check between chunks (a
//! run's log chunks, a sweep's runs), so the command stops cleanly and its
//! `Drop`s remove what it had staged. A command busy in a long computation that
//! does not check the flag is stopped after [`GRACE`]: the thread removes every
//! registered path itself (waiting for a commit in progress to finish) and exits
//! with status 128 + the signal's number.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicI32, Ordering};
use std::sync::{Mutex, MutexGuard, PoisonError};
use std::time::Duration;

/// How long a command has to stop by itself after a signal.
pub const GRACE: Duration = Duration::from_secs(2);

/// A path to remove if the process is stopped by a signal.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Cleanup {
    /// A staging folder, removed with its content.
    Tree(PathBuf),
    /// A temporary file or a lock file.
    File(PathBuf),
    /// A folder made for the output, removed only if still empty.
    EmptyDir(PathBuf),
}

impl Cleanup {
    fn path(&self) -> &Path {
        match self {
            Cleanup::Tree(p) | Cleanup::File(p) | Cleanup::EmptyDir(p) => p,
        }
    }
}

static REGISTRY: Mutex<Vec<Cleanup>> = Mutex::new(Vec::new());
static SIGNAL: AtomicI32 = AtomicI32::new(0);

fn registry() -> MutexGuard<'static, Vec<Cleanup>> {
    REGISTRY.lock().unwrap_or_else(PoisonError::into_inner)
}

/// Remove `path` if the process is stopped by a signal.
pub fn register(c: Cleanup) {
    registry().push(c);
}

/// Forget `path` (it was committed or removed).
pub fn deregister(path: &Path) {
    registry().retain(|c| c.path() != path);
}

/// Hold off the signal cleanup (while a commit renames files into place).
pub(crate) fn hold() -> MutexGuard<'static, Vec<Cleanup>> {
    registry()
}

/// [`deregister`] while holding the registry.
pub(crate) fn deregister_held(guard: &mut MutexGuard<'static, Vec<Cleanup>>, path: &Path) {
    guard.retain(|c| c.path() != path);
}

/// The signal that stopped the command (2 = SIGINT, 15 = SIGTERM, 1 = SIGHUP),
/// if one arrived.
pub fn interrupted() -> Option<i32> {
    match SIGNAL.load(Ordering::Relaxed) {
        0 => None,
        s => Some(s),
    }
}

/// Remove every registered path now (the signal thread's last step).
fn clean_up(list: &mut Vec<Cleanup>) {
    // Folders made for the output last: their staging content goes first.
    list.sort_by_key(|c| matches!(c, Cleanup::EmptyDir(_)));
    for c in list.drain(..) {
        let _ = match &c {
            // The command may still be writing into it: try a few times.
            Cleanup::Tree(p) => (0..5)
                .map(|_| std::fs::remove_dir_all(p))
                .find(|r| r.is_ok() || !p.exists())
                .unwrap_or(Ok(())),
            Cleanup::File(p) => std::fs::remove_file(p),
            Cleanup::EmptyDir(p) => std::fs::remove_dir(p),
        };
    }
}

/// Catch SIGINT, SIGTERM and SIGHUP for the rest of the process (see the module
/// documentation). Call once, from a binary.
pub fn install() -> std::io::Result<()> {
    use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
    let mut signals = signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP])?;
    std::thread::Builder::new()
        .name("nanomotion-signals".into())
        .spawn(move || {
            if let Some(sig) = signals.forever().next() {
                SIGNAL.store(sig, Ordering::Relaxed);
                // The command stops by itself if it checks the flag.
                std::thread::sleep(GRACE);
                let mut list = registry();
                clean_up(&mut list);
                std::process::exit(128 + sig);
            }
        })?;
    Ok(())
}

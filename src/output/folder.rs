//! Atomic output folders, shared by every command that writes one (`run`,
//! `diagnose`, `synth`, `reproduce`, `sweep`, `optimize-waveform`,
//! `scan-image`): files are written into a hidden staging folder and put in
//! place only when all are complete, so a reader sees the previous complete
//! content or the new complete content, never a half-written file.
//!
//! - [`OutputFolder::prepare`] replaces the target's content whole (stale files
//!   of an earlier output never stay beside new ones). The staging folder is a
//!   hidden sibling renamed over the target in one step; when the target is a
//!   mount point (a container volume, NFS, USB) or its parent cannot be written,
//!   the staging folder is made *inside* the target and its entries are renamed
//!   in one by one, with the manifest removed first and written last.
//! - [`OutputFolder::add_to`] adds files to a folder that keeps its other
//!   entries (a sweep's `rows.jsonl`, a run folder's heat maps): staged inside,
//!   renamed in.
//! - Staging folders carry the writing process's id
//!   (`.OUT.partial-PID-N`, `.nanomotion.partial-PID-N`); those of processes
//!   that no longer run (a `kill -9`, a power cut) are removed the next time
//!   the folder is prepared, and a previous output moved aside by a commit that
//!   was cut short is put back.
//! - On SIGINT, SIGTERM or SIGHUP ([`super::signals`]) the staging folders and
//!   locks of the process are removed before it exits.
//! - [`FolderLock`] keeps two processes from writing one resumable folder (a
//!   sweep's rows) at once; the lock of a process that no longer runs is taken
//!   over.

use super::OutputError;
use super::signals::{self, Cleanup};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

/// Name of the manifest written last into every output folder: a folder without
/// it is not complete (and a folder with it came from `nanomotion`).
pub const MANIFEST: &str = "nanomotion-run.json";

/// Name of the lock file of a folder being written by a resumable command.
pub const LOCK_FILE: &str = ".nanomotion.lock";

/// Prefix of a staging folder made inside the target.
const INSIDE_PREFIX: &str = ".nanomotion.partial-";

/// What the caller tells the manifest (`nanomotion-run.json`); the folder adds
/// the list of files and `complete: true`.
#[derive(Debug, Clone, Copy)]
pub struct Manifest<'a> {
    /// The command that wrote the folder (`run`, `diagnose`, `synth`, ...).
    pub command: &'a str,
    /// The input file (graph, model, config or study; empty for `reproduce`).
    pub graph: &'a str,
    /// Title of the graph or study, if any.
    pub title: &'a Option<String>,
    /// What the stability gate let through and why (`require: allow_unproven`
    /// reasons, or the refusal that `--allow-unproven` overrode); empty when
    /// every loop was proven or the command has no gate.
    pub stability_gate: &'a [String],
}

#[derive(Serialize)]
struct ManifestFile<'a> {
    command: &'a str,
    #[serde(skip_serializing_if = "no_text")]
    graph: &'a str,
    title: &'a Option<String>,
    files: Vec<String>,
    complete: bool,
    stability_gate: &'a [String],
}

fn no_text(s: &&str) -> bool {
    s.is_empty()
}

/// Where the staging folder is and how its entries reach the target.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Placement {
    /// A hidden sibling renamed over the target (`replace`: the target holds
    /// earlier content, moved aside during the rename and then removed).
    Sibling { replace: bool },
    /// Inside the target, entries renamed in one by one (`replace`: the
    /// target's other entries are removed first).
    Inside { replace: bool },
}

/// An output folder being written; see the module documentation. Dropped
/// without [`OutputFolder::commit`] (an error, a panic), the staging folder is
/// removed (and a target this folder created, if still empty).
#[derive(Debug)]
pub struct OutputFolder {
    target: PathBuf,
    staging: PathBuf,
    placement: Placement,
    /// The target was made by [`OutputFolder::add_to`].
    created: bool,
    committed: bool,
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> OutputError + '_ {
    move |source| OutputError::Io {
        path: path.display().to_string(),
        source,
    }
}

fn folder_err(target: &Path, problem: String, fix: &str) -> OutputError {
    OutputError::Folder {
        path: target.display().to_string(),
        problem,
        fix: fix.into(),
    }
}

/// The target's parent (`.` for a bare name).
fn parent_of(target: &Path) -> PathBuf {
    match target.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

fn name_of(target: &Path) -> String {
    target
        .file_name()
        .map_or_else(|| "out".into(), |n| n.to_string_lossy().into_owned())
}

/// A staging name unique in this process: `{prefix}{pid}-{n}`.
fn staging_name(prefix: &str) -> String {
    static NEXT: AtomicUsize = AtomicUsize::new(0);
    format!(
        "{prefix}{}-{}",
        std::process::id(),
        NEXT.fetch_add(1, Ordering::Relaxed)
    )
}

/// Whether process `pid` runs (a process we may not signal runs too).
pub fn process_alive(pid: u32) -> bool {
    if pid == std::process::id() {
        return true;
    }
    #[cfg(unix)]
    {
        let Ok(p) = libc::pid_t::try_from(pid) else {
            return false;
        };
        if p <= 0 {
            return false;
        }
        // SAFETY: kill with signal 0 only checks that the process exists.
        let r = unsafe { libc::kill(p, 0) };
        r == 0 || std::io::Error::last_os_error().raw_os_error() != Some(libc::ESRCH)
    }
    #[cfg(not(unix))]
    {
        // No cheap check: never take another process's files.
        true
    }
}

/// The process id in a staging or lock name after `prefix` (`123` of
/// `.out.partial-123-4.old`).
fn pid_after(name: &str, prefix: &str) -> Option<u32> {
    let rest = name.strip_prefix(prefix)?;
    let digits: String = rest.chars().take_while(char::is_ascii_digit).collect();
    digits.parse().ok()
}

/// Remove the entries of `dir` named `prefix` + PID… of processes that no
/// longer run. A previous output moved aside (`….old`) by a commit cut short
/// is put back at `restore` when that is missing.
fn remove_stale(dir: &Path, prefix: &str, restore: Option<&Path>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.filter_map(Result::ok) {
        let name = e.file_name().to_string_lossy().into_owned();
        let Some(pid) = pid_after(&name, prefix) else {
            continue;
        };
        if process_alive(pid) {
            continue;
        }
        let path = e.path();
        if name.ends_with(".old")
            && let Some(target) = restore
            && !target.exists()
            && std::fs::rename(&path, target).is_ok()
        {
            tracing::warn!(
                "put back {} (moved aside by process {pid}, which stopped before it finished writing)",
                target.display()
            );
            continue;
        }
        let removed = if path.is_dir() {
            std::fs::remove_dir_all(&path)
        } else {
            std::fs::remove_file(&path)
        };
        match removed {
            Ok(()) => tracing::warn!(
                "removed {}, left by process {pid}, which no longer runs",
                path.display()
            ),
            Err(err) => tracing::warn!("cannot remove stale {}: {err}", path.display()),
        }
    }
}

/// Whether `dir` is a mount point (its device differs from its parent's, or it
/// is the root).
fn is_mount_point(dir: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt as _;
        match (std::fs::metadata(dir), std::fs::metadata(dir.join(".."))) {
            (Ok(a), Ok(b)) => a.dev() != b.dev() || a.ino() == b.ino(),
            _ => false,
        }
    }
    #[cfg(not(unix))]
    {
        let _ = dir;
        false
    }
}

/// The entries of `dir`, without staging folders and the lock.
fn visible_entries(dir: &Path) -> Result<Vec<String>, OutputError> {
    Ok(std::fs::read_dir(dir)
        .map_err(io(dir))?
        .filter_map(Result::ok)
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| !n.starts_with(INSIDE_PREFIX) && n != LOCK_FILE)
        .collect())
}

/// Refuse a non-empty `target` that holds neither a [`MANIFEST`] nor one of
/// `ours` (a sweep's `rows.jsonl`): a folder of the user's (`--out
/// examples/diagnose`) is never written into. `fix` is the first way out.
pub fn refuse_foreign(target: &Path, ours: &[&str], fix: &str) -> Result<(), OutputError> {
    if !target.is_dir() {
        return Ok(());
    }
    let entries = visible_entries(target)?;
    if entries.is_empty()
        || entries
            .iter()
            .any(|e| e == MANIFEST || ours.contains(&e.as_str()))
    {
        return Ok(());
    }
    let mut shown: Vec<&str> = entries.iter().take(3).map(String::as_str).collect();
    if entries.len() > 3 {
        shown.push("...");
    }
    Err(folder_err(
        target,
        format!(
            "is not empty and does not hold a previous nanomotion output ({} entries: {})",
            entries.len(),
            shown.join(", ")
        ),
        &format!("{fix}, or choose another --out"),
    ))
}

impl OutputFolder {
    /// Check `target` before the work starts and make the staging folder.
    ///
    /// - a missing folder is created (with its parents) at commit;
    /// - a folder holding a previous complete output (its [`MANIFEST`]) is
    ///   replaced;
    /// - an empty folder is used;
    /// - any other non-empty folder is refused unless `force`, then replaced
    ///   whole;
    /// - a file, or a folder that cannot be written, is an error now.
    ///
    /// Stale staging folders of processes that no longer run are removed first.
    pub fn prepare(target: &Path, force: bool) -> Result<Self, OutputError> {
        let parent = parent_of(target);
        let name = name_of(target);
        let sibling_prefix = format!(".{name}.partial-");
        remove_stale(&parent, &sibling_prefix, Some(target));
        let mut replace = false;
        let mut exists = false;
        match std::fs::metadata(target) {
            Ok(m) if !m.is_dir() => {
                return Err(folder_err(
                    target,
                    "is a file, not a folder".into(),
                    "pass another --out, or remove the file",
                ));
            }
            Ok(_) => {
                exists = true;
                remove_stale(target, INSIDE_PREFIX, None);
                if !force {
                    refuse_foreign(target, &[], "pass --force to replace its whole content")?;
                }
                replace = !visible_entries(target)?.is_empty();
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(io(target)(e)),
        }
        if exists && is_mount_point(target) {
            return Self::inside(target, Placement::Inside { replace }, false);
        }
        std::fs::create_dir_all(&parent).map_err(io(&parent))?;
        let staging = parent.join(staging_name(&sibling_prefix));
        match std::fs::create_dir(&staging) {
            Ok(()) => {}
            // The parent cannot take a sibling (read-only, no permission) but
            // the target itself may be writable: stage inside it.
            Err(_) if exists => {
                return Self::inside(target, Placement::Inside { replace }, false);
            }
            Err(e) => return Err(io(&staging)(e)),
        }
        signals::register(Cleanup::Tree(staging.clone()));
        Ok(Self {
            target: target.to_path_buf(),
            staging,
            placement: Placement::Sibling { replace },
            created: false,
            committed: false,
        })
    }

    /// Add files to `target` (created if missing), keeping its other entries:
    /// staged inside it, renamed in at [`OutputFolder::commit`]. Stale staging
    /// folders of processes that no longer run are removed first.
    pub fn add_to(target: &Path) -> Result<Self, OutputError> {
        match std::fs::metadata(target) {
            Ok(m) if !m.is_dir() => Err(folder_err(
                target,
                "is a file, not a folder".into(),
                "pass another --out, or remove the file",
            )),
            Ok(_) => Self::inside(target, Placement::Inside { replace: false }, false),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                std::fs::create_dir_all(target).map_err(io(target))?;
                signals::register(Cleanup::EmptyDir(target.to_path_buf()));
                Self::inside(target, Placement::Inside { replace: false }, true)
            }
            Err(e) => Err(io(target)(e)),
        }
    }

    fn inside(target: &Path, placement: Placement, created: bool) -> Result<Self, OutputError> {
        remove_stale(target, INSIDE_PREFIX, None);
        let staging = target.join(staging_name(INSIDE_PREFIX));
        if let Err(e) = std::fs::create_dir(&staging) {
            if created {
                let _ = std::fs::remove_dir(target);
                signals::deregister(target);
            }
            return Err(io(target)(e));
        }
        signals::register(Cleanup::Tree(staging.clone()));
        Ok(Self {
            target: target.to_path_buf(),
            staging,
            placement,
            created,
            committed: false,
        })
    }

    /// The folder to write the files into (the staging folder).
    pub fn dir(&self) -> &Path {
        &self.staging
    }

    /// The final folder.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Whether the files are renamed into the target one by one (a mount point,
    /// a parent that cannot be written, or [`OutputFolder::add_to`]).
    pub fn stages_inside(&self) -> bool {
        matches!(self.placement, Placement::Inside { .. })
    }

    /// Write the manifest (if any) last, then put the files in place. Returns
    /// the final paths of the files written (the manifest last).
    pub fn commit(mut self, manifest: Option<&Manifest<'_>>) -> Result<Vec<PathBuf>, OutputError> {
        let mut names: Vec<String> = std::fs::read_dir(&self.staging)
            .map_err(io(&self.staging))?
            .filter_map(Result::ok)
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n != MANIFEST)
            .collect();
        names.sort();
        if let Some(m) = manifest {
            let path = self.staging.join(MANIFEST);
            let file = ManifestFile {
                command: m.command,
                graph: m.graph,
                title: m.title,
                files: names.clone(),
                complete: true,
                stability_gate: m.stability_gate,
            };
            let text = serde_json::to_string_pretty(&file).map_err(|e| OutputError::Csv {
                path: path.display().to_string(),
                message: e.to_string(),
            })?;
            std::fs::write(&path, text).map_err(io(&path))?;
            names.push(MANIFEST.to_string());
        }
        // A signal's cleanup waits until the files are in place; after a
        // signal nothing new is put in place.
        let mut guard = signals::hold();
        if let Some(signal) = signals::interrupted() {
            drop(guard);
            return Err(OutputError::Interrupted { signal });
        }
        match self.placement {
            Placement::Sibling { replace } => self.commit_sibling(replace, &names)?,
            Placement::Inside { replace } => {
                self.commit_inside(replace, manifest.is_some(), &names)?;
            }
        }
        signals::deregister_held(&mut guard, &self.staging);
        if self.created {
            signals::deregister_held(&mut guard, &self.target);
        }
        drop(guard);
        self.committed = true;
        Ok(names.iter().map(|n| self.target.join(n)).collect())
    }

    fn commit_sibling(&mut self, replace: bool, names: &[String]) -> Result<(), OutputError> {
        let target = self.target.clone();
        // Another command may have written the target since `prepare` (two runs
        // into one --out): its complete output is replaced like any previous one.
        let appeared = !replace && target.is_dir() && !visible_entries(&target)?.is_empty();
        if appeared {
            refuse_foreign(
                &target,
                &[],
                "it was filled while this command ran: move it away",
            )?;
        }
        let replace = replace || appeared;
        let result = if replace {
            let old = self.staging.with_file_name(format!(
                "{}.old",
                self.staging
                    .file_name()
                    .unwrap_or_default()
                    .to_string_lossy()
            ));
            match std::fs::rename(&target, &old) {
                Ok(()) => {
                    if let Err(e) = std::fs::rename(&self.staging, &target) {
                        // Put the previous output back.
                        let _ = std::fs::rename(&old, &target);
                        Err(e)
                    } else {
                        std::fs::remove_dir_all(&old).map_err(io(&old))?;
                        Ok(())
                    }
                }
                Err(e) => Err(e),
            }
        } else {
            if target.exists() {
                // An empty folder made before the work.
                std::fs::remove_dir(&target).map_err(io(&target))?;
            }
            std::fs::rename(&self.staging, &target)
        };
        match result {
            Ok(()) => Ok(()),
            // The target cannot be renamed (busy: a mount point made during the
            // work; another device): move the entries instead.
            Err(_) if target.is_dir() => self.commit_inside(replace, true, names),
            Err(e) => Err(io(&target)(e)),
        }
    }

    fn commit_inside(
        &mut self,
        replace: bool,
        has_manifest: bool,
        names: &[String],
    ) -> Result<(), OutputError> {
        let target = self.target.clone();
        if has_manifest {
            // The folder reads as incomplete until the new manifest is in.
            match std::fs::remove_file(target.join(MANIFEST)) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                    return Err(io(&target.join(MANIFEST))(e));
                }
                _ => {}
            }
        }
        if replace {
            for e in visible_entries(&target)? {
                let p = target.join(&e);
                let r = if p.is_dir() && !p.is_symlink() {
                    std::fs::remove_dir_all(&p)
                } else {
                    std::fs::remove_file(&p)
                };
                r.map_err(io(&p))?;
            }
        }
        for n in names {
            let from = self.staging.join(n);
            let to = target.join(n);
            if to.is_dir() && !to.is_symlink() {
                std::fs::remove_dir_all(&to).map_err(io(&to))?;
            }
            move_entry(&from, &to)?;
        }
        std::fs::remove_dir_all(&self.staging).map_err(io(&self.staging))
    }
}

/// Rename `from` to `to`; across devices, copy (a file through a temporary
/// name beside `to`, renamed in) and remove `from`.
fn move_entry(from: &Path, to: &Path) -> Result<(), OutputError> {
    if std::fs::rename(from, to).is_ok() {
        return Ok(());
    }
    if from.is_dir() {
        std::fs::create_dir_all(to).map_err(io(to))?;
        for e in std::fs::read_dir(from).map_err(io(from))? {
            let e = e.map_err(io(from))?;
            move_entry(&e.path(), &to.join(e.file_name()))?;
        }
        return std::fs::remove_dir_all(from).map_err(io(from));
    }
    let tmp = to.with_file_name(format!(
        ".{}.partial-{}",
        to.file_name().unwrap_or_default().to_string_lossy(),
        std::process::id()
    ));
    std::fs::copy(from, &tmp)
        .and_then(|_| std::fs::rename(&tmp, to))
        .map_err(|e| {
            let _ = std::fs::remove_file(&tmp);
            io(to)(e)
        })?;
    std::fs::remove_file(from).map_err(io(from))
}

impl Drop for OutputFolder {
    fn drop(&mut self) {
        if self.committed {
            return;
        }
        let _ = std::fs::remove_dir_all(&self.staging);
        signals::deregister(&self.staging);
        if self.created {
            // Only if nothing else was put there meanwhile.
            let _ = std::fs::remove_dir(&self.target);
            signals::deregister(&self.target);
        }
    }
}

/// `message` with every staging folder in a path replaced by its target
/// (`out/.run.partial-12-0/signals.csv` → `out/run/signals.csv`,
/// `mnt/.nanomotion.partial-12-0/a.svg` → `mnt/a.svg`): an error names the
/// file the user asked for, not a hidden folder that is gone by then.
pub fn unstaged(message: &str) -> String {
    let mut out = String::with_capacity(message.len());
    let mut rest = message;
    while let Some(at) = rest.find(".partial-") {
        let start = rest[..at]
            .rfind(['/', '\\', ' ', '`', '\''])
            .map_or(0, |i| i + 1);
        let after = &rest[at + ".partial-".len()..];
        let tag = after
            .find(|c: char| !(c.is_ascii_digit() || c == '-'))
            .unwrap_or(after.len());
        let segment = &rest[start..at];
        if tag == 0 || !segment.starts_with('.') {
            out.push_str(&rest[..at + 1]);
            rest = &rest[at + 1..];
            continue;
        }
        out.push_str(&rest[..start]);
        let mut next = &after[tag..];
        if segment == INSIDE_PREFIX.trim_end_matches(".partial-") {
            // Inside the target: drop the segment and its separator.
            next = next.strip_prefix(['/', '\\']).unwrap_or(next);
        } else {
            out.push_str(&segment[1..]);
        }
        rest = next;
    }
    out.push_str(rest);
    out
}

/// Write `contents` to `path` whole or not at all: into a hidden temporary
/// file beside it (named with the process id), then renamed over `path`.
pub fn write_atomic(path: &Path, contents: impl AsRef<[u8]>) -> Result<(), OutputError> {
    let tmp = path.with_file_name(format!(
        ".{}.partial-{}",
        path.file_name().unwrap_or_default().to_string_lossy(),
        std::process::id()
    ));
    signals::register(Cleanup::File(tmp.clone()));
    let r = std::fs::write(&tmp, contents).and_then(|()| std::fs::rename(&tmp, path));
    if r.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    signals::deregister(&tmp);
    r.map_err(io(path))
}

/// A lock on a folder written by a long, resumable command (a sweep's rows):
/// the file [`LOCK_FILE`] inside it holds the process id. Released on drop.
#[derive(Debug)]
pub struct FolderLock {
    path: PathBuf,
    /// The folder was made for this lock (removed on drop if left empty).
    created: Option<PathBuf>,
}

impl FolderLock {
    /// Lock `dir` (created if missing). A lock of a running process is an
    /// error naming it; the lock of a process that no longer runs is taken
    /// over.
    pub fn acquire(dir: &Path) -> Result<Self, OutputError> {
        let created = if dir.exists() {
            None
        } else {
            std::fs::create_dir_all(dir).map_err(io(dir))?;
            signals::register(Cleanup::EmptyDir(dir.to_path_buf()));
            Some(dir.to_path_buf())
        };
        let lock = Self::take(dir);
        if lock.is_err()
            && let Some(d) = &created
        {
            let _ = std::fs::remove_dir(d);
            signals::deregister(d);
        }
        lock.map(|path| Self { path, created })
    }

    /// Whether the folder was made for this lock (it did not exist).
    pub fn created_folder(&self) -> bool {
        self.created.is_some()
    }

    fn take(dir: &Path) -> Result<PathBuf, OutputError> {
        let path = dir.join(LOCK_FILE);
        let pid = std::process::id();
        for _ in 0..4 {
            // The lock appears whole: written under a private name, then
            // linked in (fails if a lock exists).
            let own = dir.join(format!("{LOCK_FILE}.{pid}"));
            if let Err(e) = std::fs::write(&own, format!("{pid}\n")) {
                let _ = std::fs::remove_file(&own);
                return Err(io(&own)(e));
            }
            let linked = std::fs::hard_link(&own, &path);
            let _ = std::fs::remove_file(&own);
            match linked {
                Ok(()) => {
                    signals::register(Cleanup::File(path.clone()));
                    return Ok(path);
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
                // A file system without hard links: create it exclusively.
                Err(_) => match std::fs::OpenOptions::new()
                    .write(true)
                    .create_new(true)
                    .open(&path)
                {
                    Ok(mut f) => {
                        use std::io::Write as _;
                        f.write_all(format!("{pid}\n").as_bytes())
                            .map_err(io(&path))?;
                        signals::register(Cleanup::File(path.clone()));
                        return Ok(path);
                    }
                    Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
                    Err(e) => return Err(io(&path)(e)),
                },
            }
            let holder = std::fs::read_to_string(&path)
                .ok()
                .and_then(|t| t.trim().parse::<u32>().ok());
            match holder {
                Some(h) if process_alive(h) => {
                    return Err(folder_err(
                        dir,
                        format!(
                            "is being written by another nanomotion process (PID {h}{}; lock file {LOCK_FILE})",
                            if h == pid { ", this one" } else { "" }
                        ),
                        "wait until it finishes, or pass another --out",
                    ));
                }
                Some(h) => {
                    tracing::warn!(
                        "{}: taking over the lock of process {h}, which no longer runs",
                        dir.display()
                    );
                    let _ = std::fs::remove_file(&path);
                }
                // Being written (or unreadable): try again shortly.
                None => std::thread::sleep(std::time::Duration::from_millis(50)),
            }
        }
        Err(folder_err(
            dir,
            format!("its lock file {LOCK_FILE} cannot be taken"),
            "check that no other nanomotion process writes into it, remove the lock file, or pass another --out",
        ))
    }
}

impl Drop for FolderLock {
    fn drop(&mut self) {
        let ours = std::fs::read_to_string(&self.path)
            .ok()
            .and_then(|t| t.trim().parse::<u32>().ok())
            == Some(std::process::id());
        if ours {
            let _ = std::fs::remove_file(&self.path);
        }
        signals::deregister(&self.path);
        if let Some(d) = &self.created {
            // Only if nothing was written there.
            let _ = std::fs::remove_dir(d);
            signals::deregister(d);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("nm-folder-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// The id of a process that has ended.
    fn dead_pid() -> u32 {
        let mut c = std::process::Command::new("true").spawn().unwrap();
        let pid = c.id();
        c.wait().unwrap();
        assert!(!process_alive(pid));
        pid
    }

    const M: Manifest<'static> = Manifest {
        command: "test",
        graph: "g.yaml",
        title: &None,
        stability_gate: &[],
    };

    #[test]
    fn stale_partials_of_dead_processes_are_removed_and_live_ones_kept() {
        let d = scratch("stale");
        let dead = dead_pid();
        let stale = d.join(format!(".out.partial-{dead}"));
        std::fs::create_dir_all(stale.join("x")).unwrap();
        // A live process's staging folder (ours, under another counter) stays.
        let live = d.join(format!(".out.partial-{}-999", std::process::id()));
        std::fs::create_dir_all(&live).unwrap();
        // A commit cut short between its two renames: the previous output is
        // aside and the target missing; it is put back.
        let aside = d.join(format!(".out.partial-{dead}-3.old"));
        std::fs::create_dir_all(&aside).unwrap();
        std::fs::write(aside.join(MANIFEST), "{}").unwrap();
        let target = d.join("out");
        let f = OutputFolder::prepare(&target, false).unwrap();
        assert!(!stale.exists() && live.exists());
        assert!(target.join(MANIFEST).exists(), "previous output put back");
        drop(f);
        // Inside a target (a mount point's staging) too.
        let inside = target.join(format!("{INSIDE_PREFIX}{dead}-0"));
        std::fs::create_dir_all(&inside).unwrap();
        let f = OutputFolder::add_to(&target).unwrap();
        assert!(!inside.exists());
        drop(f);
        std::fs::remove_dir_all(&d).ok();
    }

    #[test]
    fn inside_commit_replaces_entries_and_writes_the_manifest_last() {
        let d = scratch("inside");
        let target = d.join("out");
        std::fs::create_dir_all(&target).unwrap();
        std::fs::write(target.join(MANIFEST), "{}").unwrap();
        std::fs::write(target.join("old.csv"), "old").unwrap();
        let f = OutputFolder::inside(&target, Placement::Inside { replace: true }, false).unwrap();
        std::fs::write(f.dir().join("new.csv"), "new").unwrap();
        let files = f.commit(Some(&M)).unwrap();
        assert_eq!(
            files,
            vec![target.join("new.csv"), target.join(MANIFEST)],
            "manifest last"
        );
        let mut left: Vec<String> = std::fs::read_dir(&target)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        left.sort();
        assert_eq!(left, vec![MANIFEST.to_string(), "new.csv".to_string()]);
        let m: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(target.join(MANIFEST)).unwrap()).unwrap();
        assert_eq!(m["files"], serde_json::json!(["new.csv"]));
        assert_eq!(m["command"], "test");
        // add_to keeps the other entries; an uncommitted one leaves nothing.
        let f = OutputFolder::add_to(&target).unwrap();
        std::fs::write(f.dir().join("more.svg"), "x").unwrap();
        drop(f);
        assert!(!target.join("more.svg").exists());
        assert_eq!(visible_entries(&target).unwrap().len(), 2);
        let missing = d.join("fresh");
        drop(OutputFolder::add_to(&missing).unwrap());
        assert!(!missing.exists(), "a folder made for nothing is removed");
        std::fs::remove_dir_all(&d).ok();
    }

    #[test]
    fn an_output_committed_meanwhile_by_another_command_is_replaced() {
        let d = scratch("race");
        let target = d.join("out");
        let a = OutputFolder::prepare(&target, false).unwrap();
        let b = OutputFolder::prepare(&target, false).unwrap();
        std::fs::write(a.dir().join("a.csv"), "a").unwrap();
        std::fs::write(b.dir().join("b.csv"), "b").unwrap();
        a.commit(Some(&M)).unwrap();
        b.commit(Some(&M)).unwrap();
        assert!(target.join("b.csv").exists() && !target.join("a.csv").exists());
        assert_eq!(partials_in(&d), 0);
        std::fs::remove_dir_all(&d).ok();
    }

    fn partials_in(d: &Path) -> usize {
        std::fs::read_dir(d)
            .unwrap()
            .filter(|e| {
                e.as_ref()
                    .unwrap()
                    .file_name()
                    .to_string_lossy()
                    .contains(".partial-")
            })
            .count()
    }

    #[test]
    fn errors_name_the_target_not_the_staging_folder() {
        assert_eq!(
            unstaged("error: full/.s.partial-12-0/controller.yaml: No space left"),
            "error: full/s/controller.yaml: No space left"
        );
        assert_eq!(
            unstaged("cannot write `mnt/.nanomotion.partial-7-3/a.svg`: busy"),
            "cannot write `mnt/a.svg`: busy"
        );
        assert_eq!(
            unstaged("x.partial-y and .a.partial-z"),
            "x.partial-y and .a.partial-z"
        );
    }

    #[test]
    fn a_lock_of_a_live_process_is_refused_and_of_a_dead_one_taken_over() {
        let d = scratch("lock");
        let a = FolderLock::acquire(&d).unwrap();
        let e = FolderLock::acquire(&d).unwrap_err().to_string();
        assert!(
            e.contains(&format!("PID {}", std::process::id())) && e.contains("another --out"),
            "{e}"
        );
        drop(a);
        assert!(!d.join(LOCK_FILE).exists());
        std::fs::write(d.join(LOCK_FILE), format!("{}\n", dead_pid())).unwrap();
        let b = FolderLock::acquire(&d).unwrap();
        assert_eq!(
            std::fs::read_to_string(d.join(LOCK_FILE)).unwrap().trim(),
            std::process::id().to_string()
        );
        drop(b);
        std::fs::remove_dir_all(&d).ok();
    }
}

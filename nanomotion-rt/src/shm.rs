//! A plant in another process, over shared memory.
//!
//! `nanomotion plant GRAPH --serve NAME` runs a plant graph on its own real-time
//! loop with a [`ShmPlant`] as its device; `nanomotion rt CONTROLLER --device
//! shm:NAME` connects a controller graph to it with a [`ShmDevice`]. Both map
//! the file `/dev/shm/nanomotion-NAME`:
//!
//! | words | content |
//! |---|---|
//! | 0–15 | magic, layout version, channel counts, descriptor length, heartbeats of both sides, `controller detached` and `plant stopped` flags, plant pid |
//! | 16–1039 | descriptor (JSON: rate and channels with units), at most 8 KiB |
//! | then | controller → plant block: sequence word + one word per channel (f64 bits) |
//! | then | plant → controller block: sequence word + one word per channel |
//!
//! Each block has one writer and is published as a seqlock: the writer makes
//! the sequence odd, stores the values, makes it even; a reader retries while
//! the sequence is odd or moved. Reading and writing are a handful of atomic
//! loads and stores: no system call, no lock, bounded time (why shared memory
//! and not UDP: docs/ARCHITECTURE.md).
//!
//! Each side bumps its heartbeat on every write; the other side's read stops the
//! loop with [`DeviceError::Watchdog`] when the heartbeat stalls longer than
//! the watchdog, and with [`DeviceError::Closed`] when the other side has left
//! (the controller detaches when dropped, the plant marks itself stopped).

use crate::device::{Channel, Device, DeviceError};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering, fence};
use std::time::Duration;

const MAGIC: u64 = u64::from_le_bytes(*b"NMRTSHM1");
const VERSION: u64 = 1;
const W_MAGIC: usize = 0;
const W_VERSION: usize = 1;
const W_N_TO: usize = 2;
const W_N_FROM: usize = 3;
const W_DESC_LEN: usize = 4;
const W_PLANT_HB: usize = 5;
const W_CTRL_HB: usize = 6;
const W_CTRL_DETACHED: usize = 7;
const W_PLANT_STOPPED: usize = 8;
const W_PLANT_PID: usize = 9;
const DESC_OFF: usize = 16;
const DESC_WORDS: usize = 1024;
const TO_OFF: usize = DESC_OFF + DESC_WORDS;

/// What the plant tells a controller about itself (the descriptor).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlantInfo {
    /// Title of the plant graph.
    pub title: Option<String>,
    /// Rate of the plant's loop (Hz).
    pub rate_hz: f64,
    /// Channels the controller writes (the plant's `hw_input` blocks).
    pub to_plant: Vec<Channel>,
    /// Channels the plant publishes (its `hw_output` blocks).
    pub from_plant: Vec<Channel>,
    /// The plant graph as it runs (serde form of its `GraphSpec`, overrides
    /// applied), for the controller's stability gate
    /// ([`Device::plant_model`]); left out when it does not fit the
    /// descriptor ([`ShmPlant::serve`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub graph: Option<serde_json::Value>,
}

/// Errors of setting up the shared memory.
#[derive(Debug, thiserror::Error)]
pub enum ShmError {
    /// The name cannot be a file name.
    #[error(
        "plant name `{0}`: use 1 to 64 letters, digits, `-` or `_` (fix: e.g. `--serve stage`)"
    )]
    BadName(String),
    /// An OS call failed.
    #[error("{path}: {message}")]
    Io {
        /// The segment file.
        path: String,
        /// What failed.
        message: String,
    },
    /// No plant serves that name (yet).
    #[error(
        "no plant serves `{name}` ({path} {reason}) (fix: start `nanomotion plant PLANT.yaml --serve {name}` first)"
    )]
    NoPlant {
        /// The name.
        name: String,
        /// The segment file.
        path: String,
        /// What was seen.
        reason: String,
    },
    /// Another live plant serves that name.
    #[error("`{name}` is already served by process {pid} (fix: stop it, or serve another name)")]
    Busy {
        /// The name.
        name: String,
        /// Its process.
        pid: u64,
    },
    /// The descriptor is too long for the segment.
    #[error("the plant's channel list is {0} bytes, at most 8192 fit (fix: fewer hw blocks)")]
    TooLarge(usize),
}

/// Why a device named as the front ends name it (`shm:NAME`, a connect
/// timeout, a watchdog) could not be connected ([`ShmDevice::connect_named`]).
#[derive(Debug, thiserror::Error)]
pub enum ConnectError {
    /// Not `shm:NAME`.
    #[error(
        "device `{0}`: unknown device (fix: `shm:NAME` for a plant served by `nanomotion plant GRAPH --serve NAME`)"
    )]
    UnknownDevice(String),
    /// The connect timeout is not a finite number of seconds ≥ 0.
    #[error("connect timeout {0} s: must be a finite number ≥ 0 (fix: e.g. 10 s)")]
    ConnectTimeout(f64),
    /// The watchdog is out of range.
    #[error("watchdog {0} ms: must be in (0, 60000] ms (fix: e.g. 50 ms)")]
    Watchdog(f64),
    /// The segment could not be used.
    #[error(transparent)]
    Shm(#[from] ShmError),
}

/// The watchdog of a device or a served plant from milliseconds: in (0, 60000].
pub fn watchdog_ms(ms: f64) -> Result<Duration, ConnectError> {
    if !(ms.is_finite() && ms > 0.0 && ms <= 60_000.0) {
        return Err(ConnectError::Watchdog(ms));
    }
    Ok(Duration::from_secs_f64(ms * 1e-3))
}

/// The segment file of plant `name`.
pub fn segment_path(name: &str) -> Result<PathBuf, ShmError> {
    let ok = !name.is_empty()
        && name.len() <= 64
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_');
    if !ok {
        return Err(ShmError::BadName(name.into()));
    }
    Ok(PathBuf::from(format!("/dev/shm/nanomotion-{name}")))
}

/// One mapping of the segment.
struct Segment {
    ptr: *mut AtomicU64,
    words: usize,
    path: PathBuf,
}

// SAFETY: the mapping is only accessed through atomics; it lives until Drop.
unsafe impl Send for Segment {}

impl Segment {
    fn map(file: &std::fs::File, words: usize, path: PathBuf) -> Result<Self, ShmError> {
        use std::os::fd::AsRawFd;
        let bytes = words * 8;
        // SAFETY: mapping a file we opened read-write, of at least `bytes` length.
        let ptr = unsafe {
            libc::mmap(
                std::ptr::null_mut(),
                bytes,
                libc::PROT_READ | libc::PROT_WRITE,
                libc::MAP_SHARED,
                file.as_raw_fd(),
                0,
            )
        };
        if ptr == libc::MAP_FAILED {
            return Err(ShmError::Io {
                path: path.display().to_string(),
                message: format!("mmap: {}", std::io::Error::last_os_error()),
            });
        }
        Ok(Self {
            ptr: ptr.cast(),
            words,
            path,
        })
    }

    #[inline]
    fn word(&self, i: usize) -> &AtomicU64 {
        assert!(i < self.words);
        // SAFETY: in bounds (checked), page-aligned mapping, valid for the
        // lifetime of `self`; AtomicU64 has the layout of u64.
        unsafe { &*self.ptr.add(i) }
    }

    /// Publish `values` in the block at `base` (single writer).
    #[inline]
    fn publish(&self, base: usize, values: &[f64]) {
        let seq = self.word(base);
        let s = seq.load(Ordering::Relaxed);
        seq.store(s.wrapping_add(1), Ordering::Relaxed);
        fence(Ordering::Release);
        for (i, v) in values.iter().enumerate() {
            self.word(base + 1 + i)
                .store(v.to_bits(), Ordering::Relaxed);
        }
        seq.store(s.wrapping_add(2), Ordering::Release);
    }

    /// A consistent copy of the block at `base`; `false` if the writer kept it
    /// busy for 1 000 attempts (the values are then from the last attempt).
    #[inline]
    fn fetch(&self, base: usize, out: &mut [f64]) -> bool {
        let seq = self.word(base);
        for _ in 0..1000 {
            let s1 = seq.load(Ordering::Acquire);
            if s1 & 1 == 1 {
                std::hint::spin_loop();
                continue;
            }
            for (i, v) in out.iter_mut().enumerate() {
                *v = f64::from_bits(self.word(base + 1 + i).load(Ordering::Relaxed));
            }
            fence(Ordering::Acquire);
            if seq.load(Ordering::Relaxed) == s1 {
                return true;
            }
        }
        false
    }

    fn descriptor(&self) -> Result<PlantInfo, String> {
        let len = self.word(W_DESC_LEN).load(Ordering::Acquire) as usize;
        if len > DESC_WORDS * 8 {
            return Err(format!("descriptor length {len} out of range"));
        }
        let mut bytes = vec![0u8; len];
        for (i, b) in bytes.iter_mut().enumerate() {
            let w = self.word(DESC_OFF + i / 8).load(Ordering::Relaxed);
            *b = w.to_le_bytes()[i % 8];
        }
        serde_json::from_slice(&bytes).map_err(|e| e.to_string())
    }
}

impl Drop for Segment {
    fn drop(&mut self) {
        // SAFETY: unmapping exactly what `map` mapped.
        unsafe { libc::munmap(self.ptr.cast(), self.words * 8) };
    }
}

fn io(path: &std::path::Path) -> impl Fn(std::io::Error) -> ShmError + '_ {
    move |e| ShmError::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

/// Heartbeat watchdog of the other side.
#[derive(Debug, Clone, Copy)]
struct Watchdog {
    limit_ns: u64,
    last: u64,
    since_ns: u64,
}

impl Watchdog {
    /// Whether the heartbeat `hb` moved within the limit at `now`.
    #[inline]
    fn alive(&mut self, hb: u64, now: u64) -> Result<(), f64> {
        if hb != self.last || self.since_ns == 0 {
            self.last = hb;
            self.since_ns = now;
            return Ok(());
        }
        let silent = now.saturating_sub(self.since_ns);
        if silent > self.limit_ns {
            Err(silent as f64 * 1e-6)
        } else {
            Ok(())
        }
    }
}

/// The plant's side of the segment: the device of `nanomotion plant`.
///
/// Its inputs are what the controller writes, its outputs what the plant
/// publishes. Before a controller connects the plant reads zeros; the plant stops
/// ([`DeviceError::Closed`]) when the controller detaches, and with a watchdog
/// error when the controller's heartbeat stalls.
pub struct ShmPlant {
    seg: Segment,
    name: String,
    info: PlantInfo,
    watchdog: Watchdog,
    tick: u64,
}

impl std::fmt::Debug for ShmPlant {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ShmPlant")
            .field("name", &self.name)
            .field("info", &self.info)
            .finish_non_exhaustive()
    }
}

impl ShmPlant {
    /// Create the segment of `name` for a plant described by `info`. A stale
    /// segment (its plant process gone) is replaced.
    pub fn serve(name: &str, info: PlantInfo, watchdog: Duration) -> Result<Self, ShmError> {
        let path = segment_path(name)?;
        if let Ok(old) = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(&path)
        {
            let len = old.metadata().map_err(io(&path))?.len() as usize;
            if len >= TO_OFF * 8 {
                let seg = Segment::map(&old, TO_OFF, path.clone())?;
                let pid = seg.word(W_PLANT_PID).load(Ordering::Acquire);
                let stopped = seg.word(W_PLANT_STOPPED).load(Ordering::Acquire) == 1;
                // SAFETY: kill with signal 0 only checks that the process exists.
                let alive = pid > 0
                    && pid != u64::from(std::process::id())
                    && unsafe { libc::kill(pid as libc::pid_t, 0) } == 0;
                if alive && !stopped {
                    return Err(ShmError::Busy {
                        name: name.into(),
                        pid,
                    });
                }
            }
            drop(old);
            std::fs::remove_file(&path).map_err(io(&path))?;
        }
        let json = |info: &PlantInfo| {
            serde_json::to_vec(info).map_err(|e| ShmError::Io {
                path: path.display().to_string(),
                message: e.to_string(),
            })
        };
        let mut info = info;
        let mut desc = json(&info)?;
        if desc.len() > DESC_WORDS * 8 && info.graph.is_some() {
            // The channels first: a plant too large to describe is served
            // without its graph (the controller's gate then has no model).
            info.graph = None;
            desc = json(&info)?;
        }
        if desc.len() > DESC_WORDS * 8 {
            return Err(ShmError::TooLarge(desc.len()));
        }
        let (n_to, n_from) = (info.to_plant.len(), info.from_plant.len());
        let words = TO_OFF + 2 + n_to + n_from;
        let tmp = path.with_extension(format!("partial-{}", std::process::id()));
        let file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create_new(true)
            .open(&tmp)
            .map_err(io(&tmp))?;
        file.set_len((words * 8) as u64).map_err(io(&tmp))?;
        let seg = Segment::map(&file, words, path.clone())?;
        for (i, chunk) in desc.chunks(8).enumerate() {
            let mut w = [0u8; 8];
            w[..chunk.len()].copy_from_slice(chunk);
            seg.word(DESC_OFF + i)
                .store(u64::from_le_bytes(w), Ordering::Relaxed);
        }
        seg.word(W_DESC_LEN)
            .store(desc.len() as u64, Ordering::Relaxed);
        seg.word(W_N_TO).store(n_to as u64, Ordering::Relaxed);
        seg.word(W_N_FROM).store(n_from as u64, Ordering::Relaxed);
        seg.word(W_VERSION).store(VERSION, Ordering::Relaxed);
        seg.word(W_PLANT_PID)
            .store(u64::from(std::process::id()), Ordering::Relaxed);
        seg.word(W_MAGIC).store(MAGIC, Ordering::Release);
        // Appear under the final name only when complete.
        std::fs::rename(&tmp, &path).map_err(io(&path))?;
        Ok(Self {
            seg,
            name: format!("shm-plant:{name}"),
            info,
            watchdog: Watchdog {
                limit_ns: watchdog.as_nanos() as u64,
                last: 0,
                since_ns: 0,
            },
            tick: 0,
        })
    }

    /// What the segment announces.
    pub fn info(&self) -> &PlantInfo {
        &self.info
    }

    /// Whether a controller has written at least once.
    pub fn controller_connected(&self) -> bool {
        self.seg.word(W_CTRL_HB).load(Ordering::Acquire) > 0
    }

    /// The controller's latest outputs (what [`Device::read`] gives the plant).
    pub fn peek_commands(&self, out: &mut [f64]) {
        self.seg.fetch(TO_OFF, out);
    }
}

impl Drop for ShmPlant {
    fn drop(&mut self) {
        self.seg.word(W_PLANT_STOPPED).store(1, Ordering::Release);
        let _ = std::fs::remove_file(&self.seg.path);
    }
}

impl Device for ShmPlant {
    fn name(&self) -> &str {
        &self.name
    }
    fn inputs(&self) -> &[Channel] {
        &self.info.to_plant
    }
    fn outputs(&self) -> &[Channel] {
        &self.info.from_plant
    }
    fn read(&mut self, now_ns: u64, inputs: &mut [f64]) -> Result<(), DeviceError> {
        self.tick += 1;
        if self.seg.word(W_CTRL_DETACHED).load(Ordering::Acquire) == 1 {
            return Err(DeviceError::Closed("the controller".into()));
        }
        let hb = self.seg.word(W_CTRL_HB).load(Ordering::Acquire);
        if hb == 0 {
            inputs.fill(0.0);
            return Ok(());
        }
        if let Err(silent_ms) = self.watchdog.alive(hb, now_ns) {
            return Err(DeviceError::Watchdog {
                device: self.name.clone(),
                silent_ms,
                limit_ms: self.watchdog.limit_ns as f64 * 1e-6,
                tick: self.tick - 1,
            });
        }
        self.seg.fetch(TO_OFF, inputs);
        Ok(())
    }
    fn write(&mut self, _now_ns: u64, outputs: &[f64]) -> Result<(), DeviceError> {
        self.seg
            .publish(TO_OFF + 1 + self.info.to_plant.len(), outputs);
        self.seg.word(W_PLANT_HB).fetch_add(1, Ordering::Release);
        Ok(())
    }
    /// A plant's outputs are measurements: nothing to make safe; the segment
    /// says the plant stopped, so the controller stops too.
    fn safe_state(&mut self) -> Result<(), DeviceError> {
        self.seg.word(W_PLANT_STOPPED).store(1, Ordering::Release);
        Ok(())
    }
}

/// The controller's side: a [`Device`] whose inputs are the plant's outputs and
/// whose outputs drive the plant. Declares one tick of transport delay.
pub struct ShmDevice {
    seg: Segment,
    name: String,
    info: PlantInfo,
    inputs: Vec<Channel>,
    outputs: Vec<Channel>,
    from_off: usize,
    watchdog: Watchdog,
    tick: u64,
}

impl std::fmt::Debug for ShmDevice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ShmDevice")
            .field("name", &self.name)
            .field("info", &self.info)
            .finish_non_exhaustive()
    }
}

impl ShmDevice {
    /// Connect to the device `spec` as the front ends name it — `shm:NAME`
    /// (`nanomotion rt --device`, Python's `device=`) — waiting up to
    /// `connect_timeout_s` for the plant to appear; the loop stops when its
    /// heartbeat stalls for longer than `watchdog_ms`. Every setting is checked
    /// before anything is opened.
    pub fn connect_named(
        spec: &str,
        connect_timeout_s: f64,
        watchdog: f64,
    ) -> Result<Self, ConnectError> {
        let Some(name) = spec.strip_prefix("shm:") else {
            return Err(ConnectError::UnknownDevice(spec.into()));
        };
        if !(connect_timeout_s.is_finite() && connect_timeout_s >= 0.0) {
            return Err(ConnectError::ConnectTimeout(connect_timeout_s));
        }
        let watchdog = watchdog_ms(watchdog)?;
        Ok(Self::connect(
            name,
            Duration::from_secs_f64(connect_timeout_s),
            watchdog,
        )?)
    }

    /// Connect to plant `name`, waiting up to `wait` for it to appear. The loop
    /// stops when the plant's heartbeat stalls for longer than `watchdog`.
    pub fn connect(name: &str, wait: Duration, watchdog: Duration) -> Result<Self, ShmError> {
        let path = segment_path(name)?;
        let start = std::time::Instant::now();
        let no_plant = |reason: String| ShmError::NoPlant {
            name: name.into(),
            path: path.display().to_string(),
            reason,
        };
        let (seg, info) = loop {
            let attempt = (|| -> Result<(Segment, PlantInfo), String> {
                let file = std::fs::OpenOptions::new()
                    .read(true)
                    .write(true)
                    .open(&path)
                    .map_err(|e| format!("cannot be opened: {e}"))?;
                let len = file.metadata().map_err(|e| e.to_string())?.len() as usize / 8;
                if len < TO_OFF + 2 {
                    return Err(format!("is {} bytes, too short", len * 8));
                }
                let seg = Segment::map(&file, len, path.clone()).map_err(|e| e.to_string())?;
                if seg.word(W_MAGIC).load(Ordering::Acquire) != MAGIC {
                    return Err("is not a nanomotion plant segment".into());
                }
                if seg.word(W_VERSION).load(Ordering::Relaxed) != VERSION {
                    return Err(
                        "has another layout version (fix: the same nanomotion on both sides)"
                            .into(),
                    );
                }
                if seg.word(W_PLANT_STOPPED).load(Ordering::Acquire) == 1 {
                    return Err("belongs to a plant that has stopped".into());
                }
                if seg.word(W_CTRL_DETACHED).load(Ordering::Acquire) == 1 {
                    return Err(
                        "was used by a controller that left (fix: restart the plant)".into(),
                    );
                }
                let info = seg.descriptor()?;
                let n = TO_OFF + 2 + info.to_plant.len() + info.from_plant.len();
                if n > len {
                    return Err("is shorter than its channel list".into());
                }
                Ok((seg, info))
            })();
            match attempt {
                Ok(x) => break x,
                Err(reason) if start.elapsed() >= wait => return Err(no_plant(reason)),
                Err(_) => std::thread::sleep(Duration::from_millis(10)),
            }
        };
        Ok(Self {
            seg,
            name: format!("shm:{name}"),
            inputs: info.from_plant.clone(),
            outputs: info.to_plant.clone(),
            from_off: TO_OFF + 1 + info.to_plant.len(),
            info,
            watchdog: Watchdog {
                limit_ns: watchdog.as_nanos() as u64,
                last: 0,
                since_ns: 0,
            },
            tick: 0,
        })
    }

    /// What the plant announced.
    pub fn info(&self) -> &PlantInfo {
        &self.info
    }
}

impl Drop for ShmDevice {
    fn drop(&mut self) {
        self.seg.word(W_CTRL_DETACHED).store(1, Ordering::Release);
    }
}

impl Device for ShmDevice {
    fn name(&self) -> &str {
        &self.name
    }
    fn inputs(&self) -> &[Channel] {
        &self.inputs
    }
    fn outputs(&self) -> &[Channel] {
        &self.outputs
    }
    fn read(&mut self, now_ns: u64, inputs: &mut [f64]) -> Result<(), DeviceError> {
        self.tick += 1;
        if self.seg.word(W_PLANT_STOPPED).load(Ordering::Acquire) == 1 {
            return Err(DeviceError::Closed("the plant".into()));
        }
        let hb = self.seg.word(W_PLANT_HB).load(Ordering::Acquire);
        if let Err(silent_ms) = self.watchdog.alive(hb, now_ns) {
            return Err(DeviceError::Watchdog {
                device: self.name.clone(),
                silent_ms,
                limit_ms: self.watchdog.limit_ns as f64 * 1e-6,
                tick: self.tick - 1,
            });
        }
        self.seg.fetch(self.from_off, inputs);
        Ok(())
    }
    fn write(&mut self, _now_ns: u64, outputs: &[f64]) -> Result<(), DeviceError> {
        self.seg.publish(TO_OFF, outputs);
        self.seg.word(W_CTRL_HB).fetch_add(1, Ordering::Release);
        Ok(())
    }
    /// Zeros to the plant, then detach: the loop has stopped and writes no
    /// more, so the plant stops now ("the controller closed the connection"),
    /// from the loop thread, rather than on its watchdog when the thread that
    /// drops this device is scheduled late.
    fn safe_state(&mut self) -> Result<(), DeviceError> {
        let zeros = vec![0.0; self.outputs.len()];
        self.write(crate::clock::now_ns(), &zeros)?;
        self.seg.word(W_CTRL_DETACHED).store(1, Ordering::Release);
        Ok(())
    }
    fn latency_ticks(&self) -> u32 {
        1
    }
    /// The graph the plant serves, if it fitted the descriptor.
    fn plant_model(&self) -> Result<Option<nanomotion_core::GraphSpec>, DeviceError> {
        self.info
            .graph
            .clone()
            .map(serde_json::from_value)
            .transpose()
            .map_err(|e| {
                DeviceError::Config(format!(
                    "{}: the plant's graph cannot be read: {e} (fix: the same nanomotion on both sides)",
                    self.name
                ))
            })
    }
}

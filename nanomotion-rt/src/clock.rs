//! The wall clock and the real-time privileges of the loop thread (Linux).
//!
//! Time is `CLOCK_MONOTONIC` in nanoseconds (read through the vDSO: no system
//! call). The loop sleeps with `clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME)`
//! until an absolute deadline, so the wake-up latency of one tick never shifts the
//! next one (a relative sleep would add every latency to the schedule).

use serde::Serialize;

/// `CLOCK_MONOTONIC` now, in nanoseconds.
#[inline]
pub fn now_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_MONOTONIC always exists on Linux.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// Sleep until `deadline_ns` on `CLOCK_MONOTONIC` (absolute), then busy-wait the
/// last `spin_ns` (0: no spin). Returns at once for a deadline in the past.
/// Interrupted sleeps (`EINTR`) are resumed: the deadline is absolute.
#[inline]
pub fn sleep_until(deadline_ns: u64, spin_ns: u64) {
    let wake = deadline_ns.saturating_sub(spin_ns);
    let ts = libc::timespec {
        tv_sec: (wake / 1_000_000_000) as libc::time_t,
        tv_nsec: (wake % 1_000_000_000) as libc::c_long,
    };
    loop {
        // SAFETY: `ts` is a valid timespec; the remaining-time pointer may be null
        // with TIMER_ABSTIME.
        let r = unsafe {
            libc::clock_nanosleep(
                libc::CLOCK_MONOTONIC,
                libc::TIMER_ABSTIME,
                &ts,
                std::ptr::null_mut(),
            )
        };
        if r != libc::EINTR {
            break;
        }
    }
    if spin_ns > 0 {
        while now_ns() < deadline_ns {
            std::hint::spin_loop();
        }
    }
}

/// What the loop thread asks the operating system for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Privileges {
    /// `SCHED_FIFO` priority (1..=99); `None`: stay at normal priority.
    pub priority: Option<u8>,
    /// Pin the loop thread to this CPU.
    pub cpu: Option<usize>,
    /// `mlockall(MCL_CURRENT | MCL_FUTURE)`: no page fault in a tick.
    pub lock_memory: bool,
    /// Keep the CPUs out of deep idle states for the run ([`CpuLatencyHold`]).
    pub hold_cpu_latency: bool,
}

/// The CPUs kept out of deep idle states while this lives: 0 µs written to
/// `/dev/cpu_dma_latency` (the kernel's PM QoS request) and the file kept open;
/// dropping it closes the file and withdraws the request. A CPU woken from a
/// deep idle state takes tens of µs more to run the loop; cyclictest holds the
/// same request by default.
#[derive(Debug)]
pub struct CpuLatencyHold {
    _file: std::fs::File,
}

/// The PM QoS file of the CPUs' wake-up latency.
pub const CPU_LATENCY_FILE: &str = "/dev/cpu_dma_latency";

impl CpuLatencyHold {
    /// Ask for 0 µs wake-up latency until the hold is dropped.
    pub fn new() -> Result<Self, Missing> {
        use std::io::Write;
        let refused = |e: std::io::Error| {
            Missing {
            what: format!("holding {CPU_LATENCY_FILE} at 0 µs (CPUs out of deep idle states)"),
            reason: e.to_string(),
            fix: "run as root, or give the user write access to /dev/cpu_dma_latency (a udev rule); or boot with `processor.max_cstate=1`".into(),
        }
        };
        let mut file = std::fs::OpenOptions::new()
            .write(true)
            .open(CPU_LATENCY_FILE)
            .map_err(refused)?;
        // The request is a binary 32-bit integer (µs).
        file.write_all(&0i32.to_ne_bytes()).map_err(refused)?;
        Ok(Self { _file: file })
    }
}

/// The CPUs' wake-up latency the kernel now grants (µs; the least of every
/// open request, 2·10⁹ when there is none), or `None` if it cannot be read.
pub fn cpu_latency_us() -> Option<i32> {
    use std::io::Read;
    let mut buf = [0u8; 4];
    let mut f = std::fs::File::open(CPU_LATENCY_FILE).ok()?;
    f.read_exact(&mut buf).ok()?;
    Some(i32::from_ne_bytes(buf))
}

/// A privilege the operating system refused, with how to grant it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Missing {
    /// What was refused (`SCHED_FIFO priority 80`, `mlockall`).
    pub what: String,
    /// The system's reason (`errno` text).
    pub reason: String,
    /// How to grant it.
    pub fix: String,
}

impl std::fmt::Display for Missing {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} refused ({}): {}", self.what, self.reason, self.fix)
    }
}

/// The CPU cannot be used (no such CPU, or outside this process's allowed set):
/// not a missing privilege but a wrong setting.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "cannot pin the loop to CPU {cpu} ({reason}) (fix: pass --cpu with a CPU of this machine that the process may use, 0..{online}, or leave it out)"
)]
pub struct BadCpu {
    /// The CPU asked for.
    pub cpu: usize,
    /// The system's reason.
    pub reason: String,
    /// CPUs online.
    pub online: usize,
}

/// Apply `p` to the calling thread. Returns the privileges that were refused
/// (empty: everything granted); a CPU that does not exist is an error.
///
/// Call it on the loop thread itself: scheduling class and affinity are
/// per-thread. `mlockall` is per-process (it also locks the other threads'
/// memory, which is what a real-time process wants).
pub fn acquire(p: &Privileges) -> Result<Vec<Missing>, BadCpu> {
    let mut missing = Vec::new();
    if let Some(cpu) = p.cpu {
        // SAFETY: a zeroed cpu_set_t is a valid empty set; CPU_SET bounds-checks
        // against the set size (cpu < CPU_SETSIZE is checked first).
        let r = unsafe {
            let mut set: libc::cpu_set_t = std::mem::zeroed();
            if cpu >= libc::CPU_SETSIZE as usize {
                -2
            } else {
                libc::CPU_SET(cpu, &mut set);
                libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set)
            }
        };
        if r != 0 {
            let reason = if r == -2 {
                "beyond CPU_SETSIZE".to_string()
            } else {
                std::io::Error::last_os_error().to_string()
            };
            return Err(BadCpu {
                cpu,
                reason,
                online: std::thread::available_parallelism().map_or(1, |n| n.get()),
            });
        }
    }
    if p.lock_memory {
        // SAFETY: plain system call without pointers.
        if unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) } != 0 {
            missing.push(Missing {
                what: "mlockall (locking the process's memory)".into(),
                reason: std::io::Error::last_os_error().to_string(),
                fix: "raise the locked-memory limit (`ulimit -l unlimited`, or `memlock` in /etc/security/limits.conf) or grant CAP_IPC_LOCK (`setcap cap_ipc_lock+ep BINARY`)".into(),
            });
        }
    }
    if let Some(prio) = p.priority {
        let param = libc::sched_param {
            sched_priority: i32::from(prio),
        };
        // SAFETY: `param` is a valid sched_param; pthread_self is the calling thread.
        let r =
            unsafe { libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_FIFO, &param) };
        if r != 0 {
            missing.push(Missing {
                what: format!("SCHED_FIFO priority {prio}"),
                reason: std::io::Error::from_raw_os_error(r).to_string(),
                fix: format!(
                    "raise the real-time priority limit (`ulimit -r {prio}`, or `rtprio` in /etc/security/limits.conf) or grant CAP_SYS_NICE (`setcap cap_sys_nice+ep BINARY`), or run as root"
                ),
            });
        }
    }
    Ok(missing)
}

/// The calling thread's scheduling policy and priority as the kernel sees them
/// (`SCHED_FIFO` is 1, `SCHED_OTHER` 0).
pub fn current_policy() -> (i32, i32) {
    let mut policy = 0;
    let mut param = libc::sched_param { sched_priority: 0 };
    // SAFETY: both pointers are valid and writable.
    unsafe { libc::pthread_getschedparam(libc::pthread_self(), &mut policy, &mut param) };
    (policy, param.sched_priority)
}

/// Touch `bytes` of the stack so that its pages are mapped (and locked, after
/// `mlockall`) before the first tick.
#[inline(never)]
pub fn prefault_stack(bytes: usize) {
    const CHUNK: usize = 16 * 1024;
    let buf = [0u8; CHUNK];
    std::hint::black_box(&buf);
    if bytes > CHUNK {
        prefault_stack(bytes - CHUNK);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn absolute_sleep_wakes_after_the_deadline() {
        let t0 = now_ns();
        let deadline = t0 + 2_000_000;
        sleep_until(deadline, 0);
        let t1 = now_ns();
        assert!(t1 >= deadline, "woke {} ns early", deadline - t1);
        // A deadline in the past returns at once.
        let t2 = now_ns();
        sleep_until(t0, 0);
        assert!(now_ns() - t2 < 1_000_000);
    }

    #[test]
    fn spinning_ends_at_the_deadline_not_before() {
        let deadline = now_ns() + 500_000;
        sleep_until(deadline, 200_000);
        assert!(now_ns() >= deadline);
    }

    #[test]
    fn a_cpu_beyond_the_machine_is_an_error_naming_it() {
        let p = Privileges {
            priority: None,
            cpu: Some(100_000),
            lock_memory: false,
            hold_cpu_latency: false,
        };
        let e = std::thread::spawn(move || acquire(&p))
            .join()
            .unwrap()
            .unwrap_err();
        assert_eq!(e.cpu, 100_000);
        assert!(e.to_string().contains("--cpu"), "{e}");
    }
}

//! Pinning threads to cores: the CPUs this process may run on (its affinity mask, which
//! `taskset` and systemd's `CPUAffinity=` set) and pinning the calling thread to one of
//! them.
//!
//! Owns only the operating system's calls. The detector's pool pins its threads with it
//! (`[pipeline] pin_threads`): after an idle gap between frames Linux wakes a pool thread
//! on the core its waker runs on, and the two then share one core for the frame; pinned,
//! each keeps its own. On systems other than Linux nothing is pinned.

use std::io;

/// The CPUs this process may run on, ascending. Empty when they cannot be read (or off
/// Linux).
pub fn allowed_cpus() -> Vec<usize> {
    imp::allowed_cpus()
}

/// Pins the calling thread to `cpu`.
pub fn pin_current_thread(cpu: usize) -> io::Result<()> {
    imp::pin_current_thread(cpu)
}

/// The CPUs the calling thread may run on, ascending (empty off Linux).
pub fn current_thread_cpus() -> Vec<usize> {
    imp::current_thread_cpus()
}

/// The CPU for thread `i` of a set pinned from the `first` allowed CPU on: the allowed CPUs
/// taken in turn, wrapping round. `None` when no CPU is known.
pub fn cpu_for(allowed: &[usize], first: usize, i: usize) -> Option<usize> {
    (!allowed.is_empty()).then(|| allowed[(first + i) % allowed.len()])
}

#[cfg(target_os = "linux")]
mod imp {
    use std::io;

    fn set_of(pid_self_thread: bool) -> Option<libc::cpu_set_t> {
        // SAFETY: cpu_set_t is plain data; an all-zero set is valid, and the kernel writes at
        // most its size.
        let mut set: libc::cpu_set_t = unsafe { std::mem::zeroed() };
        let pid = if pid_self_thread {
            0
        } else {
            // SAFETY: getpid has no preconditions.
            unsafe { libc::getpid() }
        };
        // SAFETY: `set` is a valid cpu_set_t of the size passed.
        let rc = unsafe {
            libc::sched_getaffinity(pid, std::mem::size_of::<libc::cpu_set_t>(), &mut set)
        };
        (rc == 0).then_some(set)
    }

    fn cpus(set: &libc::cpu_set_t) -> Vec<usize> {
        // SAFETY: CPU_ISSET reads the set within its fixed size.
        (0..libc::CPU_SETSIZE as usize)
            .filter(|&c| unsafe { libc::CPU_ISSET(c, set) })
            .collect()
    }

    pub fn allowed_cpus() -> Vec<usize> {
        set_of(false).map(|s| cpus(&s)).unwrap_or_default()
    }

    pub fn current_thread_cpus() -> Vec<usize> {
        set_of(true).map(|s| cpus(&s)).unwrap_or_default()
    }

    pub fn pin_current_thread(cpu: usize) -> io::Result<()> {
        if cpu >= libc::CPU_SETSIZE as usize {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!("CPU {cpu} is beyond the {} a set holds", libc::CPU_SETSIZE),
            ));
        }
        // SAFETY: as in `set_of`; CPU_SET writes within the set (cpu checked above).
        let mut set: libc::cpu_set_t = unsafe { std::mem::zeroed() };
        unsafe { libc::CPU_SET(cpu, &mut set) };
        // SAFETY: `set` is a valid cpu_set_t of the size passed; 0 is the calling thread.
        let rc =
            unsafe { libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) };
        if rc == 0 {
            Ok(())
        } else {
            Err(io::Error::last_os_error())
        }
    }
}

#[cfg(not(target_os = "linux"))]
mod imp {
    use std::io;

    pub fn allowed_cpus() -> Vec<usize> {
        Vec::new()
    }

    pub fn current_thread_cpus() -> Vec<usize> {
        Vec::new()
    }

    pub fn pin_current_thread(_cpu: usize) -> io::Result<()> {
        Err(io::Error::new(
            io::ErrorKind::Unsupported,
            "pinning threads is implemented on Linux only",
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cpus_are_taken_in_turn_from_the_first() {
        let allowed = [2, 3, 6];
        let got: Vec<_> = (0..4).map(|i| cpu_for(&allowed, 1, i).unwrap()).collect();
        assert_eq!(got, vec![3, 6, 2, 3]);
        assert_eq!(cpu_for(&[], 0, 0), None);
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn a_pinned_thread_runs_on_its_cpu_only() {
        let allowed = allowed_cpus();
        assert!(!allowed.is_empty(), "the process's CPUs could not be read");
        let last = *allowed.last().unwrap();
        let got = std::thread::spawn(move || {
            pin_current_thread(last).unwrap();
            current_thread_cpus()
        })
        .join()
        .unwrap();
        assert_eq!(got, vec![last]);
        // the process's own mask is untouched
        assert_eq!(allowed_cpus(), allowed);
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn a_cpu_beyond_the_set_is_refused() {
        let e = std::thread::spawn(|| pin_current_thread(1 << 20))
            .join()
            .unwrap()
            .unwrap_err();
        assert!(e.to_string().contains("CPU 1048576"), "{e}");
    }
}

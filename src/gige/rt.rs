//! Real-time scheduling for the threads that receive camera data.
//!
//! Tries SCHED_FIFO for the calling thread (permitted with CAP_SYS_NICE or an RLIMIT_RTPRIO
//! allowance) and logs the outcome either way: a GigE stream thread preempted for a few
//! milliseconds loses packets.

/// Outcome of a request for real-time priority.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RtOutcome {
    /// SCHED_FIFO at this priority.
    Fifo(i32),
    /// Not permitted or failed; the errno.
    Denied(i32),
    /// Not asked for in the configuration.
    NotRequested,
}

/// Puts the calling thread under SCHED_FIFO at `priority` (1..=99), logging the result with
/// the thread's role.
pub fn make_current_thread_realtime(role: &str, priority: i32) -> RtOutcome {
    let param = libc::sched_param {
        sched_priority: priority,
    };
    // SAFETY: sched_setscheduler with pid 0 affects only the calling thread; `param` is a
    // valid sched_param that outlives the call.
    let rc = unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) };
    if rc == 0 {
        tracing::info!(thread = role, priority, "real-time priority: SCHED_FIFO");
        RtOutcome::Fifo(priority)
    } else {
        let errno = std::io::Error::last_os_error();
        tracing::warn!(
            thread = role,
            error = %errno,
            "real-time priority not granted (needs CAP_SYS_NICE or RLIMIT_RTPRIO); running at normal priority"
        );
        RtOutcome::Denied(errno.raw_os_error().unwrap_or(0))
    }
}

/// The calling thread's scheduling policy (for tests and status).
pub fn current_policy() -> i32 {
    // SAFETY: no arguments besides the calling thread's id 0.
    unsafe { libc::sched_getscheduler(0) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outcome_matches_policy() {
        // Runs in its own thread so the test harness's threads keep their policy.
        std::thread::spawn(|| match make_current_thread_realtime("test", 1) {
            RtOutcome::Fifo(p) => {
                assert_eq!(p, 1);
                assert_eq!(current_policy(), libc::SCHED_FIFO);
            }
            RtOutcome::Denied(e) => {
                assert!(e == libc::EPERM || e == libc::EINVAL, "errno {e}");
                assert_eq!(current_policy(), libc::SCHED_OTHER);
            }
            RtOutcome::NotRequested => unreachable!(),
        })
        .join()
        .unwrap();
    }
}

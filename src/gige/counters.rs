//! Live acquisition counters and the camera state, shared between the acquisition thread and
//! whoever reports status (lock-free atomics, readable from any thread).

use serde::Serialize;
use std::sync::atomic::{AtomicU64, AtomicU8, Ordering};

/// Where the camera connection stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum CameraState {
    /// Looking for the camera, opening and configuring it.
    Connecting,
    /// Frames (complete or not) arrive.
    Streaming,
    /// The camera stopped answering; the reconnect loop runs.
    CameraLost,
    /// Acquisition was stopped by its owner.
    Stopped,
}

impl CameraState {
    fn from_u8(v: u8) -> Self {
        match v {
            0 => CameraState::Connecting,
            1 => CameraState::Streaming,
            2 => CameraState::CameraLost,
            _ => CameraState::Stopped,
        }
    }

    /// The status word (`connecting`, `streaming`, `camera_lost`, `stopped`).
    pub fn as_str(self) -> &'static str {
        match self {
            CameraState::Connecting => "connecting",
            CameraState::Streaming => "streaming",
            CameraState::CameraLost => "camera_lost",
            CameraState::Stopped => "stopped",
        }
    }
}

/// Counters of one acquisition, updated by its thread.
#[derive(Debug, Default)]
pub struct GigeCounters {
    state: AtomicU8,
    /// Complete frames received (handed to the sink, or `dropped` when it was full).
    pub received: AtomicU64,
    /// Buffers that came back incomplete (missing packets, timeout, size mismatch, ...) and
    /// went straight back to the stream.
    pub incomplete: AtomicU64,
    /// Frames the camera sent that never arrived at all (gaps in its block ids).
    pub missing: AtomicU64,
    /// Pops that waited `pop_timeout` without any buffer.
    pub timeouts: AtomicU64,
    /// Complete frames the sink refused (channel full): their buffers were recycled.
    pub dropped: AtomicU64,
    /// Successful reconnections after a loss.
    pub reconnects: AtomicU64,
    /// Failed attempts to open the camera.
    pub connect_failures: AtomicU64,
    /// Frame buffers (`Vec<u8>`) allocated because none came back for reuse; flat in steady
    /// state when the consumer returns its buffers.
    pub frame_allocations: AtomicU64,
    /// Buffers queued in the Aravis stream (input + output) after the last push: equals the
    /// configured pool minus those being filled; a steady fall would be a leak.
    pub stream_buffers: AtomicU64,
}

/// A consistent-enough copy of the counters for reporting.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct GigeSnapshot {
    pub state: CameraState,
    pub received: u64,
    pub incomplete: u64,
    pub missing: u64,
    pub timeouts: u64,
    pub dropped: u64,
    pub reconnects: u64,
    pub connect_failures: u64,
    pub frame_allocations: u64,
    pub stream_buffers: u64,
}

impl GigeCounters {
    pub fn new() -> Self {
        let c = GigeCounters::default();
        c.set_state(CameraState::Connecting);
        c
    }

    pub fn state(&self) -> CameraState {
        CameraState::from_u8(self.state.load(Ordering::Acquire))
    }

    pub fn set_state(&self, s: CameraState) {
        self.state.store(s as u8, Ordering::Release);
    }

    /// Adds one to a counter.
    pub fn bump(counter: &AtomicU64) {
        counter.fetch_add(1, Ordering::Relaxed);
    }

    pub fn snapshot(&self) -> GigeSnapshot {
        let l = |a: &AtomicU64| a.load(Ordering::Relaxed);
        GigeSnapshot {
            state: self.state(),
            received: l(&self.received),
            incomplete: l(&self.incomplete),
            missing: l(&self.missing),
            timeouts: l(&self.timeouts),
            dropped: l(&self.dropped),
            reconnects: l(&self.reconnects),
            connect_failures: l(&self.connect_failures),
            frame_allocations: l(&self.frame_allocations),
            stream_buffers: l(&self.stream_buffers),
        }
    }
}

/// How many frames the camera advanced from block id `last` to `id`: 1 for consecutive
/// frames, more when frames went missing. GigE Vision 1.x block ids are 16 bits and skip 0 when
/// they wrap (65535 → 1); 64-bit ids (GigE Vision 2) never wrap in practice. An id that goes
/// backwards otherwise (camera restarted) counts as one step.
pub fn block_id_step(last: u64, id: u64) -> u64 {
    if id > last {
        id - last
    } else if last <= 0xFFFF && id >= 1 && last > 0xFF00 && id < 0x100 {
        (0xFFFF - last) + id
    } else {
        1
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn state_round_trips() {
        let c = GigeCounters::new();
        assert_eq!(c.state(), CameraState::Connecting);
        for s in [
            CameraState::Streaming,
            CameraState::CameraLost,
            CameraState::Stopped,
            CameraState::Connecting,
        ] {
            c.set_state(s);
            assert_eq!(c.state(), s);
            assert_eq!(c.snapshot().state, s);
        }
        assert_eq!(
            serde_json::to_string(&CameraState::CameraLost).unwrap(),
            "\"camera_lost\""
        );
    }

    #[test]
    fn block_ids_step_and_wrap() {
        assert_eq!(block_id_step(10, 11), 1);
        assert_eq!(block_id_step(10, 13), 3);
        assert_eq!(block_id_step(65535, 1), 1);
        assert_eq!(block_id_step(65534, 2), 3);
        assert_eq!(block_id_step(500, 3), 1); // camera restarted
        assert_eq!(block_id_step(7, 7), 1);
        assert_eq!(block_id_step(1 << 40, (1 << 40) + 2), 2);
    }

    #[test]
    fn snapshot_reads_counts() {
        let c = GigeCounters::new();
        GigeCounters::bump(&c.received);
        GigeCounters::bump(&c.received);
        GigeCounters::bump(&c.incomplete);
        let s = c.snapshot();
        assert_eq!((s.received, s.incomplete, s.timeouts), (2, 1, 0));
    }
}

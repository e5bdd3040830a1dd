//! Recycling of frame buffers (`Vec<u8>`) between the acquisition thread and its consumer.
//!
//! Frames leave the acquisition thread as owned [`crate::frame::Frame`]s. When the consumer is
//! done with one it sends `frame.data` back through [`FramePool::recycler`]; the next frame is
//! copied into a returned buffer, so steady state allocates nothing. A buffer is allocated
//! only when none has come back (warm-up, or a consumer that keeps its frames) and each such
//! allocation is counted.

use crossbeam_channel::{Receiver, Sender, TrySendError};

/// The acquisition side of the buffer pool.
#[derive(Debug)]
pub struct FramePool {
    tx: Sender<Vec<u8>>,
    rx: Receiver<Vec<u8>>,
}

/// What [`FramePool::take`] did to produce a buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Taken {
    /// A returned buffer was reused as is.
    Reused,
    /// A new buffer was allocated, or a returned one was too small and grew.
    Allocated,
}

impl FramePool {
    /// A pool that holds at most `capacity` idle buffers (extra returns are freed).
    pub fn new(capacity: usize) -> Self {
        let (tx, rx) = crossbeam_channel::bounded(capacity.max(1));
        FramePool { tx, rx }
    }

    /// The handle consumers send finished buffers to (clone it freely).
    pub fn recycler(&self) -> Recycler {
        Recycler {
            tx: self.tx.clone(),
        }
    }

    /// A buffer of exactly `len` bytes (contents unspecified), reusing a returned one when
    /// possible.
    pub fn take(&self, len: usize) -> (Vec<u8>, Taken) {
        match self.rx.try_recv() {
            Ok(mut v) => {
                let grew = v.capacity() < len;
                // Contents are overwritten by the caller; resize only touches the tail.
                v.resize(len, 0);
                (
                    v,
                    if grew {
                        Taken::Allocated
                    } else {
                        Taken::Reused
                    },
                )
            }
            Err(_) => (vec![0u8; len], Taken::Allocated),
        }
    }

    /// Puts a buffer back (used for frames the sink refused).
    pub fn give_back(&self, v: Vec<u8>) {
        let _ = self.tx.try_send(v);
    }

    /// Idle buffers waiting for reuse.
    pub fn idle(&self) -> usize {
        self.rx.len()
    }
}

/// Sends finished frame buffers back to the acquisition thread.
#[derive(Debug, Clone)]
pub struct Recycler {
    tx: Sender<Vec<u8>>,
}

impl Recycler {
    /// Returns a buffer for reuse. Never blocks: when the pool is full or gone the buffer is
    /// freed.
    pub fn recycle(&self, v: Vec<u8>) {
        match self.tx.try_send(v) {
            Ok(()) | Err(TrySendError::Full(_)) | Err(TrySendError::Disconnected(_)) => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reuses_returned_buffers() {
        let pool = FramePool::new(4);
        let (a, t) = pool.take(1000);
        assert_eq!(t, Taken::Allocated);
        let ptr = a.as_ptr();
        pool.recycler().recycle(a);
        let (b, t) = pool.take(1000);
        assert_eq!(t, Taken::Reused);
        assert_eq!(b.as_ptr(), ptr);
        assert_eq!(b.len(), 1000);
        pool.give_back(b);
        let (c, t) = pool.take(2000);
        assert_eq!(t, Taken::Allocated);
        assert_eq!(c.len(), 2000);
        let (d, t) = pool.take(10);
        assert_eq!((d.len(), t), (10, Taken::Allocated));
    }

    #[test]
    fn full_pool_frees_extra() {
        let pool = FramePool::new(2);
        let r = pool.recycler();
        for _ in 0..5 {
            r.recycle(vec![0; 8]);
        }
        assert_eq!(pool.idle(), 2);
        drop(pool);
        r.recycle(vec![1]); // pool gone: freed, no panic
    }
}

//! The tracker's prediction handed from the publisher to the detector workers, the same on
//! every run.
//!
//! Owns [`PriorBoard`]. With `[pipeline] narrow_search`, each frame's search is narrowed by
//! the row tracker's prediction ([`DetectorPrior`]), which the publisher computes as it
//! releases estimates in frame order. The frame with ticket `t` searches with the prediction
//! left after frame `t − lag` (`lag` = the number of workers; the first `lag` frames search in
//! full): its worker waits until the publisher has tracked that frame. Which prediction a
//! frame gets therefore depends only on the frames before it, not on when its worker started,
//! and two replays of one recording give the same estimates. With one worker the frame
//! searches with the previous frame's prediction, as `omnirow eval guidance` and `omnirow
//! sim` do. The wait costs nothing at the camera's rate (the worker is idle until the next
//! frame arrives) and the publisher's tracking time (well under a millisecond) back to back.
//! Tickets the publisher skips as lost (a worker died mid-frame) count as tracked; a
//! publisher silent for [`MAX_WAIT`] or gone releases the workers with the latest prediction,
//! so a stalled publisher never stalls detection. Nothing is allocated after [`PriorBoard::new`].

use crate::detect::DetectorPrior;
use std::collections::VecDeque;
use std::sync::{Condvar, Mutex};
use std::time::{Duration, Instant};

/// Longest a worker waits for the publisher before it searches with the latest prediction.
pub const MAX_WAIT: Duration = Duration::from_secs(1);

/// Where the publisher leaves each frame's prediction and the workers take theirs.
#[derive(Debug)]
pub struct PriorBoard {
    lag: u64,
    board: Mutex<Board>,
    posted: Condvar,
}

#[derive(Debug)]
struct Board {
    /// Every ticket below this has been tracked or skipped.
    next: u64,
    /// The latest `keep` tickets' predictions, oldest first.
    recent: VecDeque<(u64, Option<DetectorPrior>)>,
    keep: usize,
    /// The publisher is gone: nothing more will be posted.
    closed: bool,
}

impl Board {
    /// The prediction of the latest ticket at or before `ticket` (`None`: none kept).
    fn at_or_before(&self, ticket: u64) -> Option<DetectorPrior> {
        self.recent
            .iter()
            .rev()
            .find(|(t, _)| *t <= ticket)
            .and_then(|(_, p)| *p)
    }

    /// The latest prediction posted.
    fn latest(&self) -> Option<DetectorPrior> {
        self.recent.back().and_then(|(_, p)| *p)
    }
}

impl PriorBoard {
    /// A board for `workers` detector workers (at least one).
    pub fn new(workers: usize) -> Self {
        let lag = workers.max(1);
        PriorBoard {
            lag: lag as u64,
            board: Mutex::new(Board {
                next: 0,
                // a waiting worker's ticket t: posted tickets lie in [t − lag, t − 1]
                recent: VecDeque::with_capacity(lag + 2),
                keep: lag + 2,
                closed: false,
            }),
            posted: Condvar::new(),
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Board> {
        self.board.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The publisher tracked the frame with `ticket` (tickets come in order) and predicts
    /// `prior` for the frames after it.
    pub fn post(&self, ticket: u64, prior: Option<DetectorPrior>) {
        let mut b = self.lock();
        if b.recent.len() >= b.keep {
            b.recent.pop_front();
        }
        b.recent.push_back((ticket, prior));
        b.next = b.next.max(ticket + 1);
        drop(b);
        self.posted.notify_all();
    }

    /// The publisher gave up on every ticket below `next` (lost with a worker).
    pub fn skip_to(&self, next: u64) {
        let mut b = self.lock();
        if next > b.next {
            b.next = next;
            drop(b);
            self.posted.notify_all();
        }
    }

    /// The publisher is gone: release every waiting worker.
    pub fn close(&self) {
        self.lock().closed = true;
        self.posted.notify_all();
    }

    /// The prediction the frame with `ticket` searches with: the one left after ticket
    /// `ticket − lag`, waited for in steps of at most `step` (`beat` runs after each). After
    /// [`MAX_WAIT`], or once the publisher is gone, the latest prediction posted.
    pub fn prior_for(
        &self,
        ticket: u64,
        step: Duration,
        mut beat: impl FnMut(),
    ) -> Option<DetectorPrior> {
        let want = ticket.checked_sub(self.lag)?;
        let start = Instant::now();
        let mut b = self.lock();
        while b.next <= want {
            if b.closed || start.elapsed() >= MAX_WAIT {
                tracing::debug!(
                    ticket,
                    "prior: the publisher is late; the latest prediction"
                );
                return b.latest();
            }
            b = self
                .posted
                .wait_timeout(b, step)
                .unwrap_or_else(|e| e.into_inner())
                .0;
            beat();
        }
        b.at_or_before(want)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Mounting;
    use std::sync::Arc;

    fn prior(heading: f64) -> Option<DetectorPrior> {
        Some(DetectorPrior::from_heading_tilt(
            heading,
            0.0,
            0.05,
            &Mounting::default(),
        ))
    }

    const STEP: Duration = Duration::from_millis(10);

    #[test]
    fn the_first_frames_search_in_full_and_each_later_one_takes_the_frame_lag_before() {
        let b = PriorBoard::new(2);
        assert_eq!(b.prior_for(0, STEP, || {}), None);
        assert_eq!(b.prior_for(1, STEP, || {}), None);
        for t in 0..6 {
            b.post(t, prior(t as f64 * 0.01));
        }
        // the publisher is ahead of these (a replay cannot be, but the lookup must hold)
        assert_eq!(b.prior_for(6, STEP, || {}), prior(0.04));
        assert_eq!(b.prior_for(7, STEP, || {}), prior(0.05));
    }

    #[test]
    fn a_worker_waits_for_its_frame_and_takes_that_frames_prediction() {
        let b = Arc::new(PriorBoard::new(1));
        b.post(0, prior(0.0));
        let (tx, rx) = std::sync::mpsc::channel();
        let worker = {
            let b = b.clone();
            std::thread::spawn(move || {
                let mut beats = 0;
                let p = b.prior_for(2, STEP, || beats += 1);
                tx.send(()).unwrap();
                p
            })
        };
        // ticket 1 is not tracked yet: the worker of ticket 2 must still be waiting
        assert!(rx.recv_timeout(Duration::from_millis(50)).is_err());
        b.post(1, prior(0.1));
        rx.recv_timeout(MAX_WAIT).unwrap();
        assert_eq!(worker.join().unwrap(), prior(0.1));
    }

    #[test]
    fn skipped_tickets_count_as_tracked_and_give_the_last_prediction_before_them() {
        let b = PriorBoard::new(1);
        b.post(0, prior(0.0));
        b.post(1, prior(0.1));
        b.skip_to(4);
        assert_eq!(b.prior_for(4, STEP, || {}), prior(0.1));
        // a lost tracker predicts nothing: the next frame searches in full
        b.post(4, None);
        assert_eq!(b.prior_for(5, STEP, || {}), None);
    }

    #[test]
    fn a_closed_board_releases_its_workers_with_the_latest_prediction() {
        let b = Arc::new(PriorBoard::new(1));
        b.post(0, prior(0.2));
        let waiting = {
            let b = b.clone();
            std::thread::spawn(move || b.prior_for(5, STEP, || {}))
        };
        b.close();
        assert_eq!(waiting.join().unwrap(), prior(0.2));
    }

    #[test]
    fn only_the_latest_tickets_are_kept() {
        let b = PriorBoard::new(1);
        for t in 0..100 {
            b.post(t, prior(t as f64 * 1e-3));
        }
        let kept = b.lock().recent.len();
        assert_eq!(kept, 3);
        assert_eq!(b.prior_for(100, STEP, || {}), prior(0.099));
    }
}

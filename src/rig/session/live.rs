//! What a live view of a run reads: the run's latest status and its recent samples, thinned.
//!
//! Owns [`LiveFeed`], which the session writes while it runs and a viewer reads (the
//! `live` module's web page, through [`LiveFeed::snapshot`]); and the one way a viewer acts
//! on the run, [`LiveFeed::request_stop`], which sets the session's cancel flag, so the run
//! stops exactly as on Ctrl-C. The session pushes one point per [`LIVE_STEP_DEG`] of driver
//! travel and its status at every poll; a reader asks for the points after the last one it
//! saw, so any number of readers, coming and going, see the same run. It does not serve
//! anything, draw anything, or decide when a run ends.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};

use serde::Serialize;

use super::watch::FollowerError;
use crate::rig::recording::Phase;

/// Driver travel between two points of the feed, deg. 0.5°: 720 points a revolution, finer
/// than a chart on a screen resolves, and at 30 rpm 360 points a second (a 1 kHz bench's
/// samples thinned about three times).
pub const LIVE_STEP_DEG: f64 = 0.5;

/// Points the feed keeps, the newest: 8 192, over eleven revolutions at [`LIVE_STEP_DEG`],
/// so a page opened (or reopened) during a run shows the cycles so far, in a few hundred
/// kilobytes.
pub const LIVE_KEEP: usize = 8192;

/// One thinned sample.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LivePoint {
    /// Its number in the feed (from 0, one per point pushed).
    pub seq: u64,
    /// `settle`, `forward` or `reverse`.
    pub phase: &'static str,
    /// Driver angle as recorded (cumulative), deg.
    pub driver_deg: f64,
    /// Follower error against the target, deg, when the sample had a fresh reading.
    pub error_deg: Option<f64>,
    /// Whether the error is against the target aligned with the follower (after the first
    /// stretch of the run), rather than against the first reading.
    pub aligned: bool,
    /// Target angle about z, deg (1R and 1R1T rigs with a rotary sensor).
    pub target_deg: Option<f64>,
    /// Measured follower angle about z in the target's frame, deg (target plus error).
    pub follower_deg: Option<f64>,
}

/// The run's latest status.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct LiveStatus {
    /// `settle`, `forward` or `reverse`.
    pub phase: &'static str,
    /// Cycles done in the current direction (fractional).
    pub cycle: f64,
    /// Cycles planned per direction.
    pub cycles: u32,
    /// Samples recorded.
    pub samples: u64,
    /// Sample rate over the last progress interval, Hz.
    pub sample_rate_hz: f64,
    /// Holes in the recording so far.
    pub gaps: u64,
    /// Latest follower error, deg.
    pub error_deg: Option<f64>,
    /// Latest driver angle, deg.
    pub driver_deg: f64,
    /// Seconds since the start.
    pub elapsed_s: f64,
}

/// What a reader gets: the run, its status and the points after the one it asked from.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LiveSnapshot {
    /// The target's name (motion or mechanism), once the run has started.
    pub target: Option<String>,
    /// The motion class (`1R`, `1R1T`, `3R`).
    pub class: Option<String>,
    /// The latest status, once the session has reported one.
    pub status: Option<LiveStatus>,
    /// How the run ended, once it has (the session's end reason, or its error).
    pub ended: Option<String>,
    /// A stop was asked for by a viewer.
    pub stop_requested: bool,
    /// The points numbered `since` and later that the feed still holds, oldest first.
    pub points: Vec<LivePoint>,
    /// The number to ask from next time.
    pub next: u64,
}

#[derive(Default)]
struct Inner {
    target: Option<String>,
    class: Option<String>,
    status: Option<LiveStatus>,
    ended: Option<String>,
    points: VecDeque<LivePoint>,
    next: u64,
    last_driver_deg: Option<f64>,
}

/// A run's live status and thinned samples, shared between the session and its viewers.
pub struct LiveFeed {
    inner: Mutex<Inner>,
    cancel: Arc<AtomicBool>,
    stop_requested: AtomicBool,
}

impl LiveFeed {
    /// A feed for the run that `cancel` stops (the session's [`super::MeasureOptions`]
    /// flag).
    pub fn new(cancel: Arc<AtomicBool>) -> Arc<LiveFeed> {
        Arc::new(LiveFeed {
            inner: Mutex::new(Inner::default()),
            cancel,
            stop_requested: AtomicBool::new(false),
        })
    }

    /// The state, even after a writer panicked while holding it (the feed is display data:
    /// a half-written point is better than a viewer that fails).
    fn lock(&self) -> MutexGuard<'_, Inner> {
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The run started, towards `target` of `class`.
    pub fn begin(&self, target: &str, class: &str) {
        let mut s = self.lock();
        s.target = Some(target.to_string());
        s.class = Some(class.to_string());
    }

    /// A sample at driver angle `driver_deg` in `phase` with the probe's `error`: kept when
    /// the driver has moved [`LIVE_STEP_DEG`] since the last point kept.
    pub fn sample(&self, phase: Phase, driver_deg: f64, error: Option<FollowerError>) {
        let mut s = self.lock();
        if s.last_driver_deg
            .is_some_and(|last| (driver_deg - last).abs() < LIVE_STEP_DEG)
        {
            return;
        }
        s.last_driver_deg = Some(driver_deg);
        let seq = s.next;
        s.next += 1;
        if s.points.len() == LIVE_KEEP {
            s.points.pop_front();
        }
        s.points.push_back(LivePoint {
            seq,
            phase: phase.as_str(),
            driver_deg,
            error_deg: error.map(|e| e.deg),
            aligned: error.is_some_and(|e| e.aligned),
            target_deg: error.and_then(|e| e.target_deg),
            follower_deg: error.and_then(|e| e.target_deg.map(|t| t + e.deg)),
        });
    }

    /// The run's latest status.
    pub fn status(&self, status: LiveStatus) {
        self.lock().status = Some(status);
    }

    /// The run ended, for `why` (the end reason, or the error that ended it).
    pub fn end(&self, why: &str) {
        self.lock().ended = Some(why.to_string());
    }

    /// A viewer asks the run to stop: the session stops the motor and finishes the
    /// recording as cancelled, as on Ctrl-C.
    pub fn request_stop(&self) {
        self.stop_requested.store(true, Ordering::SeqCst);
        self.cancel.store(true, Ordering::SeqCst);
    }

    /// Whether a viewer asked the run to stop.
    pub fn stop_requested(&self) -> bool {
        self.stop_requested.load(Ordering::SeqCst)
    }

    /// The status and the points numbered `since` and later (those the feed still holds).
    pub fn snapshot(&self, since: u64) -> LiveSnapshot {
        let s = self.lock();
        let first = s.points.front().map_or(s.next, |p| p.seq);
        let skip = since.saturating_sub(first).min(s.points.len() as u64) as usize;
        LiveSnapshot {
            target: s.target.clone(),
            class: s.class.clone(),
            status: s.status.clone(),
            ended: s.ended.clone(),
            stop_requested: self.stop_requested(),
            points: s.points.iter().skip(skip).cloned().collect(),
            next: s.next,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn err(deg: f64) -> Option<FollowerError> {
        Some(FollowerError {
            deg,
            aligned: true,
            target_deg: Some(10.0),
        })
    }

    /// Guards the thinning and the reader's cursor: a point per [`LIVE_STEP_DEG`] of
    /// travel whatever the sample rate, and a reader that asks from `next` gets only what
    /// came after.
    #[test]
    fn points_are_thinned_by_travel_and_read_from_a_cursor() {
        let feed = LiveFeed::new(Arc::new(AtomicBool::new(false)));
        for i in 0..1000 {
            feed.sample(Phase::Forward, i as f64 * 0.01, err(0.5));
        }
        let all = feed.snapshot(0);
        // 0 … 9.99° in 0.01° steps: a point at 0, 0.5, …, 9.5 (steps of at least 0.5°).
        assert_eq!(all.points.len(), 20, "{:?}", all.points.len());
        assert_eq!(all.next, 20);
        let p = &all.points[3];
        assert_eq!(p.seq, 3);
        assert_eq!(p.follower_deg, Some(10.5));
        assert_eq!(p.phase, "forward");
        feed.sample(Phase::Forward, 20.0, None);
        let after = feed.snapshot(all.next);
        assert_eq!(after.points.len(), 1);
        assert_eq!(after.points[0].error_deg, None);
        assert_eq!(after.points[0].follower_deg, None);
        assert_eq!(feed.snapshot(after.next).points, vec![]);
    }

    /// Guards the bound on memory: only the newest [`LIVE_KEEP`] points are held, and a
    /// reader behind them gets what is left, numbered as before.
    #[test]
    fn only_the_newest_points_are_kept() {
        let feed = LiveFeed::new(Arc::new(AtomicBool::new(false)));
        let n = LIVE_KEEP as u64 + 100;
        for i in 0..n {
            feed.sample(Phase::Settle, i as f64, None);
        }
        let s = feed.snapshot(0);
        assert_eq!(s.points.len(), LIVE_KEEP);
        assert_eq!(s.points[0].seq, 100);
        assert_eq!(s.next, n);
        assert_eq!(feed.snapshot(n - 1).points.len(), 1);
        assert_eq!(feed.snapshot(n + 5).points.len(), 0);
    }

    /// Guards the Stop button's effect: a viewer's stop sets the session's cancel flag (the
    /// flag Ctrl-C sets) and is reported back to every viewer.
    #[test]
    fn a_viewers_stop_cancels_the_run() {
        let cancel = Arc::new(AtomicBool::new(false));
        let feed = LiveFeed::new(cancel.clone());
        assert!(!feed.snapshot(0).stop_requested);
        feed.request_stop();
        assert!(cancel.load(Ordering::SeqCst));
        assert!(feed.snapshot(0).stop_requested);
    }
}

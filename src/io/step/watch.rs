//! Watchdog threads for the STEP reader, and how their work is stopped at a timeout.
//!
//! truck can loop for a very long time on some faces (a NaN that never meets a chordal
//! tolerance makes its curve division recurse 2^100 times), and Rust cannot kill a thread.
//! So each job runs in its own thread under a timeout, and at the timeout its [`Cancel`]
//! token is set; the work polls the token and stops:
//! * our own tessellator (`conform`) and truck's tessellation and polylining evaluate their
//!   surfaces and curves through [`Guarded`], which checks the token on every evaluation;
//! * truck's code has no way to return early, so [`Guarded`] leaves it by unwinding with
//!   [`std::panic::resume_unwind`] (no panic hook, so nothing is printed), which the job's
//!   `catch_unwind` catches, also across truck's rayon jobs, which pass unwinds on to the
//!   thread that joins them.
//!
//! A job that does not stop within [`GRACE`] of its timeout (the parse, truck's conversion of
//! a face, or a loop inside truck that evaluates nothing) is abandoned and counted; a read
//! with more than [`MAX_STILL_RUNNING`] of them running fails ([`Workers::check`]) instead of
//! starting more threads that could each hold a core and memory until the process ends.

use std::panic::AssertUnwindSafe;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use truck_stepio::r#in::alias::{
    BoundedCurve, ParameterDivision1D, ParameterDivision2D, ParameterRange, ParametricCurve,
    ParametricSurface, ParametricSurface3D, SearchNearestParameter, SearchParameter, Vector3, D2,
};

use crate::error::{Error, Result};

/// How long a job may take to stop once its token is set before it is counted as still
/// running. Polled work stops at its next evaluation, microseconds later.
pub(crate) const GRACE: Duration = Duration::from_millis(500);

/// Abandoned jobs one read tolerates still running; one more fails the read.
pub(crate) const MAX_STILL_RUNNING: usize = 1;

/// The stop signal of one job.
#[derive(Clone, Debug, Default)]
pub(crate) struct Cancel(Arc<AtomicBool>);

/// The unwind payload that stops truck's code at a cancelled evaluation.
struct Cancelled;

impl Cancel {
    pub(crate) fn is_cancelled(&self) -> bool {
        self.0.load(Ordering::Relaxed)
    }

    fn cancel(&self) {
        self.0.store(true, Ordering::Relaxed);
    }

    /// Leaves the job by unwinding when it is cancelled: truck's loops have no error path
    /// to return through. `resume_unwind` runs no panic hook, so nothing is printed.
    pub(crate) fn stop_if_cancelled(&self) {
        if self.is_cancelled() {
            std::panic::resume_unwind(Box::new(Cancelled));
        }
    }
}

/// How a watched computation ended.
pub(crate) enum Watched<T> {
    Done(T),
    Panicked(String),
    /// Over its timeout; `stopped` says whether its thread has ended (else it is counted
    /// in [`Workers::still_running`]).
    TimedOut {
        stopped: bool,
    },
}

impl<T> Watched<T> {
    /// The result, or why there is none: "`what` panicked: ..." or "`what` did not finish
    /// within N s", for the message naming a skipped face.
    pub(crate) fn or_why(self, what: &str, timeout: Duration) -> std::result::Result<T, String> {
        match self {
            Watched::Done(v) => Ok(v),
            Watched::Panicked(msg) => Err(format!("{what} panicked: {msg}")),
            Watched::TimedOut { stopped } => Err(format!(
                "{what} did not finish within {:.0} s{}",
                timeout.as_secs_f64(),
                if stopped {
                    " (stopped)"
                } else {
                    " (abandoned, still running)"
                }
            )),
        }
    }
}

/// Whether a job's thread has ended and whether its waiter gave up on it, under one lock
/// so that exactly one of them counts an abandoned thread's end.
#[derive(Default)]
struct JobState {
    finished: bool,
    abandoned: bool,
}

/// The watched jobs of one read: runs them and counts those still running after their
/// timeout. Clones share the count.
#[derive(Clone, Debug, Default)]
pub(crate) struct Workers {
    still_running: Arc<AtomicUsize>,
}

impl Workers {
    /// Abandoned jobs of this read whose threads have not ended.
    pub(crate) fn still_running(&self) -> usize {
        self.still_running.load(Ordering::SeqCst)
    }

    /// An error when more abandoned jobs are running than a read tolerates: checked before
    /// each new job, so a read never piles up threads it cannot stop.
    pub(crate) fn check(&self) -> Result<()> {
        let n = self.still_running();
        if n > MAX_STILL_RUNNING {
            return Err(Error::LimitsExceeded {
                what: "STEP reader threads still running after their timeout",
                value: n as u64,
                limit: MAX_STILL_RUNNING as u64,
            });
        }
        Ok(())
    }

    /// Runs `f` in a new thread and waits at most `timeout`; then sets `f`'s token and waits
    /// [`GRACE`] more for it to stop. A thread that still runs is abandoned and counted
    /// until it ends.
    pub(crate) fn run<T: Send + 'static>(
        &self,
        name: &str,
        timeout: Duration,
        f: impl FnOnce(&Cancel) -> T + Send + 'static,
    ) -> Watched<T> {
        let cancel = Cancel::default();
        let state = Arc::new(Mutex::new(JobState::default()));
        let (tx, rx) = std::sync::mpsc::channel();
        let (job_cancel, job_state, still_running) =
            (cancel.clone(), state.clone(), self.still_running.clone());
        let spawned = std::thread::Builder::new()
            .name(name.to_string())
            .stack_size(64 << 20)
            .spawn(move || {
                let r = std::panic::catch_unwind(AssertUnwindSafe(|| f(&job_cancel)));
                let mut s = job_state.lock().unwrap_or_else(|e| e.into_inner());
                s.finished = true;
                if s.abandoned {
                    still_running.fetch_sub(1, Ordering::SeqCst);
                }
                drop(s);
                let _ = tx.send(r);
            });
        if let Err(e) = spawned {
            return Watched::Panicked(format!("cannot start a thread: {e}"));
        }
        use std::sync::mpsc::RecvTimeoutError;
        let ended = |r: std::thread::Result<T>| match r {
            Ok(v) => Watched::Done(v),
            Err(payload) if payload.is::<Cancelled>() => Watched::TimedOut { stopped: true },
            Err(payload) => Watched::Panicked(panic_message(payload.as_ref())),
        };
        match rx.recv_timeout(timeout) {
            Ok(r) => return ended(r),
            Err(RecvTimeoutError::Disconnected) => {
                return Watched::Panicked("the worker thread ended without a result".into())
            }
            Err(RecvTimeoutError::Timeout) => cancel.cancel(),
        }
        match rx.recv_timeout(GRACE) {
            // A result that came just after the timeout is late all the same.
            Ok(_) | Err(RecvTimeoutError::Disconnected) => Watched::TimedOut { stopped: true },
            Err(RecvTimeoutError::Timeout) => {
                let mut s = state.lock().unwrap_or_else(|e| e.into_inner());
                if !s.finished {
                    s.abandoned = true;
                    self.still_running.fetch_add(1, Ordering::SeqCst);
                }
                Watched::TimedOut {
                    stopped: s.finished,
                }
            }
        }
    }
}

fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "unknown panic".to_string()
    }
}

/// A curve or surface whose every evaluation first checks a job's [`Cancel`] token: what
/// truck's tessellator and polylining, and our `conform` tessellator, are given, so that
/// their loops stop at the job's timeout.
#[derive(Clone, Debug)]
pub(crate) struct Guarded<T> {
    pub(crate) inner: T,
    cancel: Cancel,
}

impl<T> Guarded<T> {
    pub(crate) fn new(inner: T, cancel: &Cancel) -> Self {
        Guarded {
            inner,
            cancel: cancel.clone(),
        }
    }

    /// The wrapped value, after unwinding out of the job if it is cancelled.
    pub(crate) fn get(&self) -> &T {
        self.cancel.stop_if_cancelled();
        &self.inner
    }
}

impl<T: ParametricCurve> ParametricCurve for Guarded<T> {
    type Point = T::Point;
    type Vector = T::Vector;
    fn subs(&self, t: f64) -> Self::Point {
        self.get().subs(t)
    }
    fn der(&self, t: f64) -> Self::Vector {
        self.get().der(t)
    }
    fn der2(&self, t: f64) -> Self::Vector {
        self.get().der2(t)
    }
    fn parameter_range(&self) -> ParameterRange {
        self.inner.parameter_range()
    }
    fn try_range_tuple(&self) -> Option<(f64, f64)> {
        self.inner.try_range_tuple()
    }
    fn period(&self) -> Option<f64> {
        self.inner.period()
    }
}

impl<T: BoundedCurve> BoundedCurve for Guarded<T> {
    fn range_tuple(&self) -> (f64, f64) {
        self.inner.range_tuple()
    }
    fn front(&self) -> Self::Point {
        self.get().front()
    }
    fn back(&self) -> Self::Point {
        self.get().back()
    }
}

impl<T: ParameterDivision1D> ParameterDivision1D for Guarded<T> {
    type Point = T::Point;
    fn parameter_division(&self, range: (f64, f64), tol: f64) -> (Vec<f64>, Vec<T::Point>) {
        self.get().parameter_division(range, tol)
    }
}

impl<T: ParametricSurface> ParametricSurface for Guarded<T> {
    type Point = T::Point;
    type Vector = T::Vector;
    fn subs(&self, u: f64, v: f64) -> Self::Point {
        self.get().subs(u, v)
    }
    fn uder(&self, u: f64, v: f64) -> Self::Vector {
        self.get().uder(u, v)
    }
    fn vder(&self, u: f64, v: f64) -> Self::Vector {
        self.get().vder(u, v)
    }
    fn uuder(&self, u: f64, v: f64) -> Self::Vector {
        self.get().uuder(u, v)
    }
    fn uvder(&self, u: f64, v: f64) -> Self::Vector {
        self.get().uvder(u, v)
    }
    fn vvder(&self, u: f64, v: f64) -> Self::Vector {
        self.get().vvder(u, v)
    }
    fn parameter_range(&self) -> (ParameterRange, ParameterRange) {
        self.inner.parameter_range()
    }
    fn try_range_tuple(&self) -> (Option<(f64, f64)>, Option<(f64, f64)>) {
        self.inner.try_range_tuple()
    }
    fn u_period(&self) -> Option<f64> {
        self.inner.u_period()
    }
    fn v_period(&self) -> Option<f64> {
        self.inner.v_period()
    }
}

impl<T: ParametricSurface3D> ParametricSurface3D for Guarded<T> {
    fn normal(&self, u: f64, v: f64) -> Vector3 {
        self.get().normal(u, v)
    }
}

impl<T: ParameterDivision2D> ParameterDivision2D for Guarded<T> {
    fn parameter_division(
        &self,
        range: ((f64, f64), (f64, f64)),
        tol: f64,
    ) -> (Vec<f64>, Vec<f64>) {
        self.get().parameter_division(range, tol)
    }
}

impl<T: SearchParameter<D2>> SearchParameter<D2> for Guarded<T> {
    type Point = T::Point;
    fn search_parameter<H: Into<<D2 as truck_stepio::r#in::alias::SPDimension>::Hint>>(
        &self,
        point: T::Point,
        hint: H,
        trials: usize,
    ) -> Option<(f64, f64)> {
        self.get().search_parameter(point, hint, trials)
    }
}

impl<T: SearchNearestParameter<D2>> SearchNearestParameter<D2> for Guarded<T> {
    type Point = T::Point;
    fn search_nearest_parameter<H: Into<<D2 as truck_stepio::r#in::alias::SPDimension>::Hint>>(
        &self,
        point: T::Point,
        hint: H,
        trials: usize,
    ) -> Option<(f64, f64)> {
        self.get().search_nearest_parameter(point, hint, trials)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Instant;

    /// A job that polls its token stops at the timeout: nothing is left running.
    #[test]
    fn a_polling_job_stops_at_its_timeout() {
        let workers = Workers::default();
        let t0 = Instant::now();
        let w = workers.run("test-poll", Duration::from_millis(50), |c: &Cancel| {
            let mut n = 0u64;
            while !c.is_cancelled() {
                n = n.wrapping_add(1);
            }
            n
        });
        assert!(matches!(w, Watched::TimedOut { stopped: true }));
        assert!(t0.elapsed() < Duration::from_millis(50) + GRACE);
        assert_eq!(workers.still_running(), 0);
        assert!(workers.check().is_ok());
    }

    /// A job stopped by unwinding out of a guarded evaluation ends as timed out (not as a
    /// panic), and prints nothing.
    #[test]
    fn a_guarded_evaluation_unwinds_out_of_the_job() {
        use truck_stepio::r#in::alias::{Line, Point3};
        let workers = Workers::default();
        let w = workers.run("test-guard", Duration::from_millis(20), |c: &Cancel| {
            let line = Guarded::new(
                Line(Point3::new(0.0, 0.0, 0.0), Point3::new(1.0, 0.0, 0.0)),
                c,
            );
            loop {
                std::hint::black_box(line.subs(0.5));
            }
        });
        assert!(matches!(w, Watched::TimedOut { stopped: true }));
        assert_eq!(workers.still_running(), 0);
    }

    /// A job that ignores its token is counted while it runs; past the limit the read
    /// stops starting jobs (a typed limit error), and the count falls when the threads end.
    #[test]
    fn jobs_that_cannot_be_stopped_are_counted_and_limited() {
        let workers = Workers::default();
        let release = Arc::new(AtomicBool::new(false));
        for k in 0..=MAX_STILL_RUNNING {
            assert!(workers.check().is_ok());
            let r = release.clone();
            let w = workers.run(
                "test-stuck",
                Duration::from_millis(10),
                move |_: &Cancel| {
                    while !r.load(Ordering::Relaxed) {
                        std::thread::sleep(Duration::from_millis(5));
                    }
                },
            );
            assert!(matches!(w, Watched::TimedOut { stopped: false }));
            assert_eq!(workers.still_running(), k + 1);
        }
        let e = workers.check().unwrap_err();
        assert!(matches!(e, Error::LimitsExceeded { .. }), "{e}");
        release.store(true, Ordering::Relaxed);
        let t0 = Instant::now();
        while workers.still_running() > 0 && t0.elapsed() < Duration::from_secs(10) {
            std::thread::sleep(Duration::from_millis(5));
        }
        assert_eq!(workers.still_running(), 0);
    }

    #[test]
    fn results_and_panics_are_reported() {
        let workers = Workers::default();
        assert!(matches!(
            workers.run("test-ok", Duration::from_secs(5), |_: &Cancel| 7),
            Watched::Done(7)
        ));
        let w = workers.run("test-panic", Duration::from_secs(5), |_: &Cancel| {
            if true {
                panic!("boom");
            }
        });
        assert!(matches!(w, Watched::Panicked(ref m) if m == "boom"));
    }
}

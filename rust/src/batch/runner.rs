//! A batch on a background thread with its own rayon pool, so a caller (Python) can show
//! progress and cancel it while the work runs. Points that could not even be built (an invalid
//! value from a sweep axis, say) are flagged `Invalid` in place; they do not stop the others.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use super::run::run_batch;
use super::{BatchConfig, PointOutput, PointSpec, Status};
use crate::error::InputError;

type Outcome = Result<Vec<PointOutput>, InputError>;

/// Set when the batch's thread ends, however it ends (dropped on every return path), so that a
/// waiter wakes at once instead of at its next poll.
type Finished = Arc<(Mutex<bool>, Condvar)>;

struct SaysFinished(Finished);

impl Drop for SaysFinished {
    fn drop(&mut self) {
        *self.0 .0.lock().unwrap_or_else(|e| e.into_inner()) = true;
        self.0 .1.notify_all();
    }
}

/// A running batch.
pub struct BatchRunner {
    cancel: Arc<AtomicBool>,
    done: Arc<AtomicUsize>,
    total: usize,
    handle: Mutex<Option<JoinHandle<Outcome>>>,
    finished: Finished,
}

impl BatchRunner {
    /// Start `points` (each built, or the reason it could not be) on `threads` worker threads.
    pub fn start(
        cfg: BatchConfig,
        points: Vec<Result<PointSpec, InputError>>,
        threads: usize,
    ) -> Result<Self, InputError> {
        cfg.validate()?;
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .map_err(|e| format!("cannot start worker threads: {e}"))?;
        let (cancel, done) = (Arc::new(AtomicBool::new(false)), Arc::new(AtomicUsize::new(0)));
        let (c2, d2) = (cancel.clone(), done.clone());
        let total = points.len();
        let finished: Finished = Arc::new((Mutex::new(false), Condvar::new()));
        let says = SaysFinished(finished.clone());
        let handle = std::thread::spawn(move || -> Outcome {
            let _says = says;
            let mut slot = Vec::with_capacity(points.len());
            let mut specs = Vec::with_capacity(points.len());
            for p in points {
                match p {
                    Ok(s) => {
                        slot.push(Ok(specs.len()));
                        specs.push(s);
                    }
                    Err(why) => {
                        slot.push(Err(why));
                        d2.fetch_add(1, Ordering::Relaxed);
                    }
                }
            }
            let run = catch_unwind(AssertUnwindSafe(|| pool.install(|| run_batch(&cfg, &specs, &c2, &d2))));
            let mut results = match run {
                Ok(r) => r.map_err(|e| e.to_string())?,
                Err(_) => return Err("internal error in idm-rs batch (please report)".into()),
            };
            Ok(slot
                .into_iter()
                .map(|s| match s {
                    Ok(k) => std::mem::replace(&mut results[k], PointOutput::with_status(Status::NotRun)),
                    Err(why) => PointOutput::invalid(why.into()),
                })
                .collect())
        });
        Ok(BatchRunner {
            cancel,
            done,
            total,
            handle: Mutex::new(Some(handle)),
            finished,
        })
    }

    /// Points finished so far.
    pub fn progress(&self) -> usize {
        self.done.load(Ordering::Relaxed)
    }

    pub fn total(&self) -> usize {
        self.total
    }

    /// Ask the workers to stop; points already finished are kept.
    pub fn cancel(&self) {
        self.cancel.store(true, Ordering::Relaxed);
    }

    /// Wait up to `timeout` [s]; true once the batch has finished (woken as it ends: a poll every
    /// 5 ms cost a small batch ~2.5 ms each, as much as its own run for one short point).
    pub fn wait(&self, timeout: f64) -> bool {
        let limit = Duration::from_secs_f64(timeout.clamp(0.0, 1e9));
        let (flag, ended) = &*self.finished;
        let guard = flag.lock().unwrap_or_else(|e| e.into_inner());
        let (guard, _) = ended
            .wait_timeout_while(guard, limit, |finished| !*finished)
            .unwrap_or_else(|e| e.into_inner());
        *guard
    }

    /// Wait for the end and take the outputs (in point order; `NotRun` where cancelled).
    pub fn join(&self) -> Result<Vec<PointOutput>, InputError> {
        let handle = self.handle.lock().unwrap().take().ok_or("result already taken")?;
        handle
            .join()
            .map_err(|_| "internal error in idm-rs batch worker (please report)".to_string())?
    }
}

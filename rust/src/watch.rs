//! A piece of work on its own thread while the calling thread waits for it and looks for a stop
//! request between waits (Ctrl-C: Python runs its signal handlers on the main thread only).

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Condvar, Mutex};
use std::time::Duration;

/// The worker's "finished" flag and the condition the waiting thread sleeps on.
pub type Done = (Mutex<bool>, Condvar);

/// Wait up to `timeout` for the worker to say it finished; true once it has.
pub fn wait_done(done: &Done, timeout: Duration) -> bool {
    let guard = done.0.lock().unwrap_or_else(|e| e.into_inner());
    let (guard, _) = done
        .1
        .wait_timeout_while(guard, timeout, |finished| !*finished)
        .unwrap_or_else(|e| e.into_inner());
    *guard
}

/// Run `work` on a worker thread; between the waits of `wait` (true once the work finished)
/// call `stop_asked`, and on a request set `cancel`, which the work polls to stop early.
///
/// Returns (the work's value, whether a stop was asked at any point), or None if `work`
/// panicked. A request is reported even when the work had finished before it saw `cancel`
/// (the request and the end crossed): `stop_asked` consumes it, so the caller must pass it on.
pub fn run_watched<T: Send>(
    cancel: &AtomicBool,
    work: impl FnOnce() -> T + Send,
    mut wait: impl FnMut(&Done) -> bool,
    mut stop_asked: impl FnMut() -> bool,
) -> Option<(T, bool)> {
    // the worker says when it is done: the wait ends then, not at the next poll
    let done: Done = (Mutex::new(false), Condvar::new());
    std::thread::scope(|scope| {
        let worker = scope.spawn(|| {
            let r = catch_unwind(AssertUnwindSafe(work));
            *done.0.lock().unwrap_or_else(|e| e.into_inner()) = true;
            done.1.notify_all();
            r
        });
        let mut asked = false;
        while !wait(&done) {
            if stop_asked() {
                cancel.store(true, Ordering::Relaxed);
                asked = true;
            }
        }
        // one more look: a request between the last look and the end is taken here too
        let asked = stop_asked() || asked;
        worker.join().ok().and_then(|r| r.ok()).map(|t| (t, asked))
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::cell::Cell;

    fn poll(done: &Done) -> bool {
        wait_done(done, Duration::from_millis(5))
    }

    #[test]
    fn a_request_seen_while_the_work_ran_on_to_its_end_is_reported() {
        // the work never looks at `cancel` (as a run in its last steps): the request must not
        // be lost with the look that consumed it
        let cancel = AtomicBool::new(false);
        let looks = Cell::new(0);
        let (value, asked) = run_watched(
            &cancel,
            || {
                std::thread::sleep(Duration::from_millis(60));
                7
            },
            poll,
            || {
                looks.set(looks.get() + 1);
                looks.get() == 1
            },
        )
        .expect("the work did not panic");
        assert_eq!(value, 7);
        assert!(asked, "a stop asked during the run was dropped");
        assert!(cancel.load(Ordering::Relaxed));
        assert!(looks.get() >= 2, "the last look after the end was skipped");
    }

    #[test]
    fn a_request_after_the_last_wait_is_reported() {
        let cancel = AtomicBool::new(false);
        let (_, asked) = run_watched(&cancel, || (), |d| wait_done(d, Duration::from_secs(5)), || true).unwrap();
        assert!(asked);
    }

    #[test]
    fn no_request_no_report_and_the_work_stops_when_cancelled() {
        let cancel = AtomicBool::new(false);
        let (value, asked) = run_watched(&cancel, || 1.5, poll, || false).unwrap();
        assert_eq!((value, asked), (1.5, false));
        assert!(!cancel.load(Ordering::Relaxed));

        // a work that runs until cancelled ends on the first request
        let cancel = AtomicBool::new(false);
        let (steps, asked) = run_watched(
            &cancel,
            || {
                let mut n = 0u64;
                while !cancel.load(Ordering::Relaxed) {
                    n += 1;
                    std::thread::sleep(Duration::from_millis(1));
                }
                n
            },
            poll,
            || true,
        )
        .unwrap();
        assert!(asked && steps < 10_000);
    }

    #[test]
    fn a_panicking_work_gives_none() {
        let cancel = AtomicBool::new(false);
        // (the panic's message is printed; the hook is global, so it is left alone)
        let r = run_watched(&cancel, || -> u8 { panic!("a panic inside the work") }, poll, || false);
        assert!(r.is_none());
    }
}

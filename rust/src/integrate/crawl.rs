//! Stopping an adaptive run whose step collapsed, instead of letting it crawl.
//!
//! `solve_ivp` stops when its step falls below 10 ulp of t; a step of 1e-12 s is far above that
//! and still hopeless over a millisecond. So every [`CRAWL_CHECK_STEPS`] accepted steps a run
//! projects, at its pace over those last steps, how many steps it needs in all to reach its
//! end; beyond [`MAX_ADAPTIVE_STEPS`] it stops as failed, with a message that says what to do
//! instead (the stepper's hint). Measured cause: an explicit method held at its stability limit
//! by a stiff friction state (a near-frictionless contact, mu = 1e-6: Dormand-Prince settles
//! at 5e-12 s steps, 2e8 for 1 ms, more than a minute without a word), where the implicit
//! method takes its accuracy's steps. The pace of the last window, not the mean since the
//! start, so that a run that turns stiff is caught within one window of turning.

/// A run projected to need more accepted steps than this stops as failed: ~35 s of one lane of
/// Dormand-Prince (340 ns a step). A paper-case run takes ~3e6 steps per simulated second, so
/// a longer record than ~30 s goes in pieces (continue from the last `State`) or with Rodas4.
pub const MAX_ADAPTIVE_STEPS: f64 = 1e8;
/// How a crawling run's message starts.
pub const CRAWL_PREFIX: &str = "the step fell to";
/// How often (in accepted steps) a run's projected step count is checked.
pub const CRAWL_CHECK_STEPS: u64 = 1 << 12;

/// One run's watch on its pace: the time of its last check.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CrawlWatch {
    t_last: f64,
}

impl CrawlWatch {
    /// A run starting at `t_start` [s].
    pub fn new(t_start: f64) -> Self {
        CrawlWatch { t_last: t_start }
    }

    /// After accepted step number `steps` (counted from 1), at time `t` [s] of a run to `t_end`:
    /// `Some(message)` when, at its pace over the last [`CRAWL_CHECK_STEPS`] steps, it would
    /// need more than [`MAX_ADAPTIVE_STEPS`] in all; checked only every CRAWL_CHECK_STEPS steps.
    /// `hint` names what to do instead.
    #[inline(always)]
    // true for NaN as well: a non-finite projection counts as beyond the bound
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    pub fn observe(&mut self, steps: u64, t: f64, t_end: f64, hint: &str) -> Option<String> {
        if steps == 0 || !steps.is_multiple_of(CRAWL_CHECK_STEPS) {
            return None;
        }
        let pace = (t - self.t_last) / CRAWL_CHECK_STEPS as f64;
        self.t_last = t;
        let projected = steps as f64 + (t_end - t) / pace;
        // also true for a pace of 0 or NaN (the comparison fails)
        (!(projected <= MAX_ADAPTIVE_STEPS)).then(|| {
            format!(
                "{CRAWL_PREFIX} {pace:.2e} s on average over the last {CRAWL_CHECK_STEPS} steps (t = {t:.6e} s, \
                 {steps} steps so far): reaching t_end = {t_end:.6e} s would take ~{projected:.1e} steps \
                 (limit {MAX_ADAPTIVE_STEPS:.0e}); {hint}"
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_crawling_run_is_stopped_with_the_projected_count() {
        let n = CRAWL_CHECK_STEPS;
        // 4,096 steps covered 4.096e-9 s of a 1 ms run: 1e9 steps to go
        let why = CrawlWatch::new(0.0)
            .observe(n, 4.096e-9, 1e-3, "use rodas4")
            .expect("crawling");
        assert!(
            why.starts_with(CRAWL_PREFIX) && why.contains("1.0e9") && why.contains("use rodas4"),
            "{why}"
        );
        // a paper-case pace (30,000 steps per 10 ms) is not
        assert!(CrawlWatch::new(0.0).observe(n, n as f64 * 3.3e-7, 10e-3, "").is_none());
        // just inside the limit is not; just outside is
        let t_end = 1e-3;
        let window = |factor: f64| n as f64 * t_end / (MAX_ADAPTIVE_STEPS * factor);
        assert!(CrawlWatch::new(0.0).observe(n, window(0.99), t_end, "").is_none());
        assert!(CrawlWatch::new(0.0).observe(n, window(1.01), t_end, "").is_some());
        assert!(
            CrawlWatch::new(0.0).observe(n - 1, 1e-20, 1e-3, "").is_none(),
            "only every CRAWL_CHECK_STEPS"
        );
        assert!(
            CrawlWatch::new(0.0).observe(n, 0.0, 1e-3, "").is_some(),
            "no progress at all"
        );
    }

    #[test]
    fn the_pace_is_the_last_windows_so_a_run_that_turns_stiff_is_caught_at_once() {
        // 20 windows at a paper-case pace cover 27 ms of a 30 ms run; then the step collapses
        let n = CRAWL_CHECK_STEPS;
        let mut w = CrawlWatch::new(0.0);
        let mut t = 0.0;
        for k in 1..=20u64 {
            t += n as f64 * 3.3e-7;
            assert!(w.observe(k * n, t, 30e-3, "").is_none());
        }
        // the mean since the start would still be ~1.6e-7 s, a few hundred thousand steps to go
        t += n as f64 * 1e-13;
        assert!(
            w.observe(21 * n, t, 30e-3, "").is_some(),
            "caught in the first window at the new pace"
        );
    }
}

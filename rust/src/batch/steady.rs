//! Steady-state actuator metrics of a sawtooth train, the numbers a designer judges a stick-slip
//! drive by: per drive cycle, the main body's step (its position at the end of the cycle minus
//! at its start) and its back-slip (the distance it travels against its net direction within
//! the cycle: the slide back that the forward stroke loses), averaged over the cycles after a
//! settable number of start-up cycles.
//!
//! Cycle boundaries are breakpoints of the input, and every method lands on breakpoints, so the
//! positions at the boundaries are states of the run, not interpolations; the travel within a
//! cycle is summed over the accepted steps (forward and backward separately, so step = forward
//! travel - backward travel exactly, whatever order the motions come in).

/// A sawtooth train's timing: `cycles` periods of `period` [s] from `start` [s].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Train {
    pub start: f64,
    pub period: f64,
    pub cycles: usize,
}

impl Train {
    /// The train of `cycles` periods at `frequency` [Hz] after `delay` [s].
    pub fn new(frequency: f64, cycles: usize, delay: f64) -> Self {
        Train {
            start: delay,
            period: 1.0 / frequency,
            cycles,
        }
    }

    /// Time of cycle boundary `k` (0 = the train's start) [s].
    #[inline(always)]
    fn boundary(&self, k: usize) -> f64 {
        self.start + k as f64 * self.period
    }
}

/// Below this share of the free stroke d33 V per cycle, the net motion counts as a stall.
pub const STALL_STEP_FRACTION: f64 = 1e-3;

/// Steady-state metrics of one point (NaN when no full cycle after the skipped ones was run).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Steady {
    /// mean step / period [m/s]
    pub mean_velocity: f64,
    /// mean step per cycle [m]
    pub step_mean: f64,
    /// standard deviation of the step over the cycles [m]
    pub step_std: f64,
    /// mean travel per cycle against the net direction [m]
    pub backslip: f64,
    /// back-slip over the travel along the net direction [-]
    pub backslip_ratio: f64,
    /// +1 forward, -1 backward, 0 stalled (|mean step| < STALL_STEP_FRACTION d33 V)
    pub direction: f64,
    /// cycles averaged
    pub cycles: f64,
}

impl Steady {
    pub fn none() -> Self {
        Steady {
            mean_velocity: f64::NAN,
            step_mean: f64::NAN,
            step_std: f64::NAN,
            backslip: f64::NAN,
            backslip_ratio: f64::NAN,
            direction: f64::NAN,
            cycles: 0.0,
        }
    }
}

/// Running per-cycle sums of one point.
#[derive(Clone, Copy, Debug)]
pub struct CycleStats {
    train: Option<Train>,
    /// first cycle that counts (start-up cycles skipped, a cycle entered mid-way never counts)
    first_counted: usize,
    /// index of the next boundary to reach
    next: usize,
    x_start: f64,
    x_prev: f64,
    /// travel forward and backward in the current cycle [m]
    up: f64,
    down: f64,
    n: f64,
    step_sum: f64,
    step_sq: f64,
    /// travel sums over the counted cycles, forward and backward [m]
    up_sum: f64,
    down_sum: f64,
    free_stroke: f64,
}

impl CycleStats {
    /// For a train (or `None`), skipping `skip` start-up cycles; `free_stroke` = d33 V [m].
    pub fn new(train: Option<Train>, skip: usize, free_stroke: f64) -> Self {
        CycleStats {
            train,
            first_counted: skip,
            next: 0,
            x_start: f64::NAN,
            x_prev: f64::NAN,
            up: 0.0,
            down: 0.0,
            n: 0.0,
            step_sum: 0.0,
            step_sq: 0.0,
            up_sum: 0.0,
            down_sum: 0.0,
            free_stroke,
        }
    }

    /// The train observed, if any.
    pub fn train(&self) -> Option<Train> {
        self.train
    }

    /// The run starts at time `t` [s] with main-body position `x` [m].
    pub fn start(&mut self, t: f64, x: f64) {
        let Some(tr) = self.train else { return };
        let tol = 1e-9 * tr.period;
        let mut k = 0;
        while k <= tr.cycles && tr.boundary(k) < t - tol {
            k += 1;
        }
        self.next = k;
        // a cycle already under way when the run starts is seen only in part
        if tr.boundary(k) > t + tol {
            self.first_counted = self.first_counted.max(k);
        }
        self.observe(t, x);
    }

    /// An accepted state at time `t` [s] with main-body position `x` [m].
    #[inline(always)]
    pub fn observe(&mut self, t: f64, x: f64) {
        let Some(tr) = self.train else { return };
        if self.next > tr.cycles {
            return;
        }
        let dx = x - self.x_prev; // NaN at the first state: no travel
        if dx > 0.0 {
            self.up += dx;
        } else if dx < 0.0 {
            self.down -= dx;
        }
        self.x_prev = x;
        if t < tr.boundary(self.next) - 1e-9 * tr.period {
            return;
        }
        if self.next >= 1 && self.next > self.first_counted {
            let step = x - self.x_start;
            self.n += 1.0;
            self.step_sum += step;
            self.step_sq += step * step;
            self.up_sum += self.up;
            self.down_sum += self.down;
        }
        self.x_start = x;
        self.up = 0.0;
        self.down = 0.0;
        self.next += 1;
    }

    /// The metrics over the counted cycles.
    pub fn finish(&self) -> Steady {
        let Some(tr) = self.train else { return Steady::none() };
        if self.n == 0.0 {
            return Steady::none();
        }
        let n = self.n;
        let mean = self.step_sum / n;
        let var = if n > 1.0 {
            ((self.step_sq - n * mean * mean) / (n - 1.0)).max(0.0)
        } else {
            0.0
        };
        let direction = if mean.abs() < STALL_STEP_FRACTION * self.free_stroke {
            0.0
        } else {
            mean.signum()
        };
        // against the net direction, and along it (a stall counts as forward)
        let (back, reach) = if direction < 0.0 {
            (self.up_sum, self.down_sum)
        } else {
            (self.down_sum, self.up_sum)
        };
        Steady {
            mean_velocity: mean / tr.period,
            step_mean: mean,
            step_std: var.sqrt(),
            backslip: back / n,
            backslip_ratio: if reach > 0.0 { back / reach } else { f64::NAN },
            direction,
            cycles: n,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A synthetic staircase: each 1 ms cycle moves +1 um then slides back 0.2 um.
    fn staircase(stats: &mut CycleStats, cycles: usize, t0: f64) {
        let mut x = 0.0;
        stats.start(t0, x);
        for c in 0..cycles {
            for (dt, dx) in [(0.5e-3, 1.0e-6), (0.5e-3, -0.2e-6)] {
                let t = t0 + c as f64 * 1e-3 + if dx > 0.0 { dt } else { 1e-3 };
                x += dx;
                stats.observe(t, x);
            }
        }
    }

    #[test]
    fn staircase_gives_its_step_backslip_and_velocity() {
        let tr = Train {
            start: 0.0,
            period: 1e-3,
            cycles: 5,
        };
        let mut s = CycleStats::new(Some(tr), 1, 10e-6);
        staircase(&mut s, 5, 0.0);
        let m = s.finish();
        assert_eq!(m.cycles, 4.0);
        assert!((m.step_mean - 0.8e-6).abs() < 1e-15);
        assert!(m.step_std < 1e-15);
        assert!((m.mean_velocity - 0.8e-3).abs() < 1e-12);
        assert!((m.backslip - 0.2e-6).abs() < 1e-15);
        assert!((m.backslip_ratio - 0.2).abs() < 1e-9);
        assert_eq!(m.direction, 1.0);
    }

    #[test]
    fn a_run_shorter_than_the_skipped_cycles_has_no_metrics() {
        let tr = Train {
            start: 0.0,
            period: 1e-3,
            cycles: 5,
        };
        let mut s = CycleStats::new(Some(tr), 5, 10e-6);
        staircase(&mut s, 5, 0.0);
        assert!(s.finish().step_mean.is_nan());
        assert!(CycleStats::new(None, 0, 1.0).finish().mean_velocity.is_nan());
    }

    #[test]
    fn a_tiny_net_motion_is_a_stall() {
        let tr = Train {
            start: 0.0,
            period: 1e-3,
            cycles: 3,
        };
        let mut s = CycleStats::new(Some(tr), 0, 10e-6);
        s.start(0.0, 0.0);
        for k in 1..=3 {
            s.observe(k as f64 * 1e-3 - 0.5e-3, 1e-6);
            s.observe(k as f64 * 1e-3, 1e-12 * k as f64);
        }
        let m = s.finish();
        assert_eq!(m.direction, 0.0);
        assert_eq!(m.cycles, 3.0);
    }
}

//! Input voltage waveforms. Every waveform idm-rs knows is piecewise linear, so one type,
//! [`PiecewiseLinear`], carries them all; `triangle` and `sawtooth` build its breakpoints.
//! Before the first breakpoint the first value holds, after the last the last value holds.

use crate::error::InputError;

/// A piecewise-linear voltage V(t) through breakpoints (t [s], V [V]), t strictly increasing.
#[derive(Clone, Debug, PartialEq)]
pub struct PiecewiseLinear {
    t: Vec<f64>,
    v: Vec<f64>,
}

impl PiecewiseLinear {
    pub fn new(t: Vec<f64>, v: Vec<f64>) -> Result<Self, InputError> {
        if t.len() != v.len() {
            return Err(crate::input!("waveform: {} times but {} voltages", t.len(), v.len()));
        }
        if t.is_empty() {
            return Err("waveform: needs at least one sample".into());
        }
        if let Some(i) = t.iter().chain(v.iter()).position(|x| !x.is_finite()) {
            return Err(crate::input!("waveform: sample {} is not finite", i % t.len()));
        }
        if let Some(i) = t.windows(2).position(|w| w[1] <= w[0]) {
            return Err(crate::input!(
                "waveform: times must increase strictly (t[{}] = {} >= t[{}] = {})",
                i,
                t[i],
                i + 1,
                t[i + 1]
            ));
        }
        Ok(PiecewiseLinear { t, v })
    }

    /// 0 V until `delay`, linear to `amplitude` at delay + rise, linear to 0 at
    /// delay + rise + fall, then 0 V.
    pub fn triangle(amplitude: f64, rise: f64, fall: f64, delay: f64) -> Result<Self, InputError> {
        positive("rise", rise)?;
        positive("fall", fall)?;
        non_negative("delay", delay)?;
        finite("amplitude", amplitude)?;
        let mut t = vec![0.0];
        let mut v = vec![0.0];
        if delay > 0.0 {
            t.push(delay);
            v.push(0.0);
        }
        t.extend([delay + rise, delay + rise + fall]);
        v.extend([amplitude, 0.0]);
        Self::new(t, v)
    }

    /// `cycles` periods of 1/frequency after `delay`. Forward: rise 0 -> A in `rise`, linear
    /// fall to 0 over the rest of the period. Backward: rise over (period - rise), fall in `rise`.
    pub fn sawtooth(
        amplitude: f64,
        frequency: f64,
        cycles: usize,
        rise: f64,
        forward: bool,
        delay: f64,
    ) -> Result<Self, InputError> {
        positive("frequency", frequency)?;
        positive("rise", rise)?;
        non_negative("delay", delay)?;
        finite("amplitude", amplitude)?;
        if cycles == 0 {
            return Err("parameter 'cycles' must be at least 1".into());
        }
        let period = 1.0 / frequency;
        if rise >= period {
            return Err(crate::input!(
                "parameter 'rise' ({rise} s) must be shorter than the period ({period} s)"
            ));
        }
        let peak_at = if forward { rise } else { period - rise };
        let mut t = vec![0.0];
        let mut v = vec![0.0];
        if delay > 0.0 {
            t.push(delay);
            v.push(0.0);
        }
        for k in 0..cycles {
            let start = delay + k as f64 * period;
            t.extend([start + peak_at, delay + (k + 1) as f64 * period]);
            v.extend([amplitude, 0.0]);
        }
        Self::new(t, v)
    }

    pub fn times(&self) -> &[f64] {
        &self.t
    }

    pub fn values(&self) -> &[f64] {
        &self.v
    }

    /// Largest |value| of the input (its amplitude for the standard waves).
    pub fn peak(&self) -> f64 {
        self.values().iter().fold(0.0f64, |a, v| a.max(v.abs()))
    }

    /// Index of the segment holding `t` (the last breakpoint at or before it), clamped.
    pub fn segment(&self, t: f64) -> usize {
        self.t.partition_point(|&ti| ti <= t).saturating_sub(1)
    }

    /// Slope dV/dt of segment `i` [V/s]; 0 outside the breakpoints.
    pub fn slope(&self, i: usize, t: f64) -> f64 {
        if t < self.t[0] || i + 1 >= self.t.len() {
            0.0
        } else {
            (self.v[i + 1] - self.v[i]) / (self.t[i + 1] - self.t[i])
        }
    }

    /// V(t) [V].
    pub fn value(&self, t: f64) -> f64 {
        if t <= self.t[0] {
            return self.v[0];
        }
        let i = self.segment(t);
        if i + 1 >= self.t.len() {
            return self.v[i];
        }
        self.v[i] + self.slope(i, t) * (t - self.t[i])
    }

    /// Breakpoints inside (0, t_end) must fall on step boundaries so that a step never straddles
    /// a kink (RK4 would lose its order). Refuses a `dt` that does not divide them and says
    /// which breakpoint and a `dt` that would.
    pub fn check_alignment(&self, dt: f64, t_end: f64) -> Result<(), InputError> {
        let misaligned = |step: f64| self.misaligned(step, t_end);
        if let Some(ti) = misaligned(dt) {
            let hint = (2..=1000)
                .map(|k| dt / k as f64)
                .find(|&d| misaligned(d).is_none())
                .map(|d| format!("dt = {d:e} s divides every breakpoint"))
                .unwrap_or_else(|| "choose a dt that divides every breakpoint time".into());
            return Err(crate::input!(
                "dt = {dt:e} s does not divide the waveform breakpoint at t = {ti:e} s \
                 (breakpoints must fall on step boundaries); {hint}"
            ));
        }
        Ok(())
    }
}

impl PiecewiseLinear {
    /// The first breakpoint inside (0, `t_end`) that is not a whole number of steps `dt` [s].
    pub fn misaligned(&self, dt: f64, t_end: f64) -> Option<f64> {
        self.t.iter().copied().filter(|&ti| ti > 0.0 && ti < t_end).find(|&ti| {
            let r = ti / dt;
            (r - r.round()).abs() > 1e-6
        })
    }
}

/// Walks a waveform's breakpoints as a run advances: segments are visited in order, so no
/// search per step. Steps never straddle a breakpoint (the driver lands on each), so the input
/// over a step is linear: V(t0 + tau) = V(t0) + slope tau.
#[derive(Clone, Copy, Debug, Default)]
pub struct Cursor {
    seg: usize,
}

impl Cursor {
    /// A cursor placed at time `t` [s].
    pub fn at(wave: &PiecewiseLinear, t: f64) -> Self {
        Cursor { seg: wave.segment(t) }
    }

    /// The segment index the cursor is on.
    pub fn segment(&self) -> usize {
        self.seg
    }

    /// Move onto the segment holding `probe` [s] (a time strictly inside the coming step, or the
    /// step's start for a step that starts exactly on a breakpoint); true if it moved.
    #[inline(always)]
    pub fn advance(&mut self, wave: &PiecewiseLinear, probe: f64) -> bool {
        let bt = &wave.t;
        let before = self.seg;
        while self.seg + 1 < bt.len() && bt[self.seg + 1] <= probe {
            self.seg += 1;
        }
        self.seg != before
    }

    /// (V(t0) [V], slope [V/s]) over a step starting at `t0` [s] inside the current segment;
    /// `probe` as for [`Cursor::advance`]. Before the first and after the last breakpoint the
    /// input holds its value (slope 0).
    #[inline(always)]
    pub fn input(&self, wave: &PiecewiseLinear, t0: f64, probe: f64) -> (f64, f64) {
        let (seg, bv) = (self.seg, &wave.v);
        if probe < wave.t[0] || seg + 1 >= wave.t.len() {
            (bv[seg], 0.0)
        } else {
            let s = wave.slope(seg, probe);
            (bv[seg] + s * (t0 - wave.t[seg]), s)
        }
    }

    /// The next breakpoint after `t` [s] (infinite after the last): where an adaptive step must
    /// land.
    #[inline(always)]
    pub fn next_breakpoint(&self, wave: &PiecewiseLinear, t: f64) -> f64 {
        let bt = &wave.t;
        if t < bt[0] {
            bt[0]
        } else if self.seg + 1 < bt.len() {
            bt[self.seg + 1]
        } else {
            f64::INFINITY
        }
    }
}

fn finite(name: &str, x: f64) -> Result<(), InputError> {
    if x.is_finite() {
        Ok(())
    } else {
        Err(crate::input!("parameter '{name}' must be finite, got {x}"))
    }
}

fn positive(name: &str, x: f64) -> Result<(), InputError> {
    finite(name, x)?;
    if x > 0.0 {
        Ok(())
    } else {
        Err(crate::input!("parameter '{name}' must be positive, got {x}"))
    }
}

fn non_negative(name: &str, x: f64) -> Result<(), InputError> {
    finite(name, x)?;
    if x >= 0.0 {
        Ok(())
    } else {
        Err(crate::input!("parameter '{name}' must be non-negative, got {x}"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn triangle_peaks_and_returns_to_zero() {
        let w = PiecewiseLinear::triangle(80.0, 0.5e-3, 9.5e-3, 0.0).unwrap();
        assert_eq!(w.value(0.0), 0.0);
        assert!((w.value(0.25e-3) - 40.0).abs() < 1e-9);
        assert!((w.value(0.5e-3) - 80.0).abs() < 1e-9);
        assert!((w.value(5.25e-3) - 40.0).abs() < 1e-9);
        assert_eq!(w.value(20e-3), 0.0);
    }

    #[test]
    fn sawtooth_directions_mirror() {
        let f = PiecewiseLinear::sawtooth(60.0, 100.0, 2, 0.5e-3, true, 2e-3).unwrap();
        let b = PiecewiseLinear::sawtooth(60.0, 100.0, 2, 0.5e-3, false, 2e-3).unwrap();
        assert_eq!(f.value(1e-3), 0.0);
        assert!((f.value(2.5e-3) - 60.0).abs() < 1e-9);
        assert!((b.value(11.5e-3) - 60.0).abs() < 1e-9);
        assert_eq!(f.value(30e-3), 0.0);
        // forward at 2 ms + x equals backward at 2 ms + (T - x) within a period
        for x in [0.1e-3, 0.4e-3, 3e-3, 9e-3] {
            assert!((f.value(2e-3 + x) - b.value(2e-3 + 10e-3 - x)).abs() < 1e-9);
        }
    }

    #[test]
    fn misaligned_step_is_refused_with_a_hint() {
        let w = PiecewiseLinear::triangle(80.0, 0.5e-3, 9.5e-3, 0.0).unwrap();
        assert!(w.check_alignment(1e-8, 10e-3).is_ok());
        let e = w.check_alignment(3e-7, 10e-3).unwrap_err();
        assert!(e.contains("5e-4") && e.contains("divides"), "{e}");
    }
}

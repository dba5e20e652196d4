//! Adaptive Dormand-Prince 5(4) with FSAL and an elementary step controller. Like `rk4`, it knows
//! nothing of the physics: the right-hand side is `f(segment, t, y, dy)`; the caller passes the
//! input's breakpoints as `stops` and the integrator lands on each exactly, never stepping
//! across a kink of the input (the method's order would be lost there).

/// Tolerances and limits.
#[derive(Clone, Debug)]
pub struct Dopri5Options {
    /// relative tolerance [-]
    pub rtol: f64,
    /// absolute tolerance, in units of each component's `scale` [-]
    pub atol: f64,
    /// characteristic magnitude of each state component (its unit); `inf` leaves a component
    /// out of the error norm
    pub scale: Vec<f64>,
    /// first trial step [s]
    pub h_init: f64,
    /// below this step the run is declared divergent [s]
    pub h_min: f64,
    /// largest step [s]
    pub h_max: f64,
}

/// Counters of a finished run.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Dopri5Stats {
    pub accepted: u64,
    pub rejected: u64,
    pub evaluations: u64,
}

const C: [f64; 7] = [0.0, 1.0 / 5.0, 3.0 / 10.0, 4.0 / 5.0, 8.0 / 9.0, 1.0, 1.0];
const A2: [f64; 1] = [1.0 / 5.0];
const A3: [f64; 2] = [3.0 / 40.0, 9.0 / 40.0];
const A4: [f64; 3] = [44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0];
const A5: [f64; 4] = [19372.0 / 6561.0, -25360.0 / 2187.0, 64448.0 / 6561.0, -212.0 / 729.0];
const A6: [f64; 5] = [9017.0 / 3168.0, -355.0 / 33.0, 46732.0 / 5247.0, 49.0 / 176.0, -5103.0 / 18656.0];
/// fifth-order weights (also the last stage's coefficients: first same as last)
const B: [f64; 6] = [35.0 / 384.0, 0.0, 500.0 / 1113.0, 125.0 / 192.0, -2187.0 / 6784.0, 11.0 / 84.0];
/// difference between the fifth- and fourth-order weights
const E: [f64; 7] = [
    71.0 / 57600.0, 0.0, -71.0 / 16695.0, 71.0 / 1920.0, -17253.0 / 339200.0, 22.0 / 525.0, -1.0 / 40.0,
];

/// Integrate `y` from `t0` to `t1`. `observe(t, y)` sees every accepted step and returns false
/// to stop early (cancellation). Errors with (t, message) when the step falls below `h_min`
/// or the state turns non-finite. Generic over the storage like `rk4`: a fixed `[f64; D]`
/// keeps the small models' stages in registers.
pub fn integrate<S, F, O>(
    mut f: F,
    t0: f64,
    t1: f64,
    stops: &[f64],
    y: &mut S,
    opts: &Dopri5Options,
    mut observe: O,
) -> Result<Dopri5Stats, (f64, String)>
where
    S: AsRef<[f64]> + AsMut<[f64]> + Clone,
    F: FnMut(usize, f64, &[f64], &mut [f64]),
    O: FnMut(f64, &[f64]) -> bool,
{
    let n = y.as_ref().len();
    let mut zero = y.clone();
    zero.as_mut().fill(0.0);
    let mut k: [S; 7] = std::array::from_fn(|_| zero.clone());
    let mut tmp = zero.clone();
    let mut y_new = zero;
    let mut stats = Dopri5Stats::default();
    let mut h = opts.h_init.min(opts.h_max);
    let in_norm = opts.scale.iter().filter(|s| s.is_finite()).count().max(1) as f64;
    // segment boundaries: every stop inside (t0, t1), then t1
    let mut ends: Vec<f64> = stops.iter().copied().filter(|&s| s > t0 && s < t1).collect();
    ends.push(t1);
    let mut t = t0;
    let mut seg = stops.iter().filter(|&&s| s <= t0).count().saturating_sub(1);
    for &end in &ends {
        f(seg, t, y.as_ref(), k[0].as_mut()); // fresh first stage: the input's slope changed
        stats.evaluations += 1;
        while t < end {
            let last = end - (t + h) < 1e-3 * h;
            let step = if last { end - t } else { h };
            for (s, a) in [(1usize, &A2[..]), (2, &A3[..]), (3, &A4[..]), (4, &A5[..]), (5, &A6[..])] {
                combine(tmp.as_mut(), y.as_ref(), step, a, &k);
                f(seg, t + C[s] * step, tmp.as_ref(), k[s].as_mut());
            }
            combine(y_new.as_mut(), y.as_ref(), step, &B, &k);
            f(seg, t + step, y_new.as_ref(), k[6].as_mut());
            stats.evaluations += 6;
            let (yv, ynv) = (y.as_ref(), y_new.as_ref());
            let mut err2 = 0.0;
            for i in 0..n {
                if opts.scale[i].is_finite() {
                    let mut e = 0.0;
                    for (j, ej) in E.iter().enumerate() {
                        e += ej * k[j].as_ref()[i];
                    }
                    let tol = opts.atol * opts.scale[i] + opts.rtol * yv[i].abs().max(ynv[i].abs());
                    err2 += (step * e / tol).powi(2);
                }
            }
            let err = (err2 / in_norm).sqrt(); // NaN when the state blew up: rejected below
            if err <= 1.0 {
                t = if last { end } else { t + step };
                y.as_mut().copy_from_slice(y_new.as_ref());
                k.swap(0, 6); // first same as last
                stats.accepted += 1;
                if !observe(t, y.as_ref()) {
                    return Ok(stats);
                }
                let grow = if err == 0.0 { 5.0 } else { (0.9 * err.powf(-0.2)).clamp(0.2, 5.0) };
                if !last || grow < 1.0 {
                    h = (step * grow).min(opts.h_max);
                }
            } else {
                stats.rejected += 1;
                let shrink = if err.is_finite() { (0.9 * err.powf(-0.2)).clamp(0.1, 0.9) } else { 0.1 };
                h = step * shrink;
                if h < opts.h_min {
                    return Err((t, format!("step size fell below {:.1e} s", opts.h_min)));
                }
            }
        }
        seg += 1;
    }
    Ok(stats)
}

/// out = y + h sum_j a_j k_j
#[inline(always)]
fn combine<S: AsRef<[f64]>>(out: &mut [f64], y: &[f64], h: f64, a: &[f64], k: &[S; 7]) {
    for i in 0..out.len() {
        let mut s = 0.0;
        for (j, aj) in a.iter().enumerate() {
            s += aj * k[j].as_ref()[i];
        }
        out[i] = y[i] + h * s;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn opts(rtol: f64) -> Dopri5Options {
        Dopri5Options { rtol, atol: rtol, scale: vec![1.0; 2], h_init: 1e-3, h_min: 1e-12, h_max: 1.0 }
    }

    #[test]
    fn harmonic_oscillator_meets_tolerance() {
        let mut y = [1.0, 0.0];
        let s = integrate(|_, _, y: &[f64], dy: &mut [f64]| { dy[0] = y[1]; dy[1] = -y[0]; },
            0.0, 10.0, &[], &mut y, &opts(1e-9), |_, _| true).unwrap();
        assert!((y[0] - 10f64.cos()).abs() < 1e-7, "{}", y[0]);
        assert!(s.accepted > 10 && s.accepted < 2000);
    }

    #[test]
    fn lands_exactly_on_stops_and_switches_segments() {
        // dy/dt = slope of the segment: 1 on [0,1), -2 on [1,3)
        let mut y = [0.0];
        let mut times = vec![];
        let o = Dopri5Options { scale: vec![1.0], ..opts(1e-10) };
        integrate(|seg, _, _: &[f64], dy: &mut [f64]| dy[0] = if seg == 0 { 1.0 } else { -2.0 },
            0.0, 3.0, &[0.0, 1.0, 3.0], &mut y, &o, |t, _| { times.push(t); true }).unwrap();
        assert!(times.contains(&1.0));
        assert!((y[0] - (1.0 - 4.0)).abs() < 1e-12, "{}", y[0]);
    }
}

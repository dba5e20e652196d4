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
const A5: [f64; 4] = [
    19372.0 / 6561.0,
    -25360.0 / 2187.0,
    64448.0 / 6561.0,
    -212.0 / 729.0,
];
const A6: [f64; 5] = [
    9017.0 / 3168.0,
    -355.0 / 33.0,
    46732.0 / 5247.0,
    49.0 / 176.0,
    -5103.0 / 18656.0,
];
/// fifth-order weights (also the last stage's coefficients: first same as last)
const B: [f64; 6] = [
    35.0 / 384.0,
    0.0,
    500.0 / 1113.0,
    125.0 / 192.0,
    -2187.0 / 6784.0,
    11.0 / 84.0,
];
/// difference between the fifth- and fourth-order weights
const E: [f64; 7] = [
    71.0 / 57600.0,
    0.0,
    -71.0 / 16695.0,
    71.0 / 1920.0,
    -17253.0 / 339200.0,
    22.0 / 525.0,
    -1.0 / 40.0,
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
    let ys: &mut [S; 1] = std::slice::from_mut(y).try_into().unwrap();
    let [r] = integrate_lanes(
        |_, seg, t, s: &[f64], ds: &mut [f64]| f(seg, t, s, ds),
        [t0],
        [t1],
        [stops],
        ys,
        [opts],
        |_, t, s: &[f64]| observe(t, s),
    );
    r
}

/// Where one lane stands.
#[derive(Clone, Copy, PartialEq)]
enum LaneState {
    /// needs a fresh first stage (start, or a new input segment)
    Fresh,
    Running,
    Done,
}

/// `L` independent adaptive integrations advanced attempt by attempt, stage by stage, so one
/// core works on several dependency chains at once (a single one is latency-bound, see rk4.rs).
/// Each lane keeps its own step size, segments and end time; its arithmetic is exactly that of
/// a one-lane run. `f(lane, segment, t, y, dy)`; `observe(lane, t, y)`.
pub fn integrate_lanes<S, F, O, const L: usize>(
    mut f: F,
    t0: [f64; L],
    t1: [f64; L],
    stops: [&[f64]; L],
    ys: &mut [S; L],
    opts: [&Dopri5Options; L],
    mut observe: O,
) -> [Result<Dopri5Stats, (f64, String)>; L]
where
    S: AsRef<[f64]> + AsMut<[f64]> + Clone,
    F: FnMut(usize, usize, f64, &[f64], &mut [f64]),
    O: FnMut(usize, f64, &[f64]) -> bool,
{
    let mut zero = ys[0].clone();
    zero.as_mut().fill(0.0);
    let mut k: [[S; 7]; L] = std::array::from_fn(|_| std::array::from_fn(|_| zero.clone()));
    let mut tmp: [S; L] = std::array::from_fn(|_| zero.clone());
    let mut y_new: [S; L] = std::array::from_fn(|_| zero.clone());
    let mut out: [Result<Dopri5Stats, (f64, String)>; L] =
        std::array::from_fn(|_| Ok(Dopri5Stats::default()));
    let mut stats = [Dopri5Stats::default(); L];
    let mut state = [LaneState::Fresh; L];
    let mut t = t0;
    let mut h: [f64; L] = std::array::from_fn(|i| opts[i].h_init.min(opts[i].h_max));
    let mut step = [0.0; L];
    let mut last = [false; L];
    // segment boundaries of each lane: every stop inside (t0, t1), then t1
    let ends: Vec<Vec<f64>> = (0..L)
        .map(|i| {
            let mut e: Vec<f64> = stops[i]
                .iter()
                .copied()
                .filter(|&s| s > t0[i] && s < t1[i])
                .collect();
            e.push(t1[i]);
            e
        })
        .collect();
    let mut end_idx = [0usize; L];
    let mut seg: [usize; L] = std::array::from_fn(|i| {
        stops[i]
            .iter()
            .filter(|&&s| s <= t0[i])
            .count()
            .saturating_sub(1)
    });
    let in_norm: [f64; L] = std::array::from_fn(|i| {
        opts[i]
            .scale
            .iter()
            .filter(|s| s.is_finite())
            .count()
            .max(1) as f64
    });
    loop {
        // start segments, or finish lanes that reached their end
        let mut any = false;
        for i in 0..L {
            if state[i] != LaneState::Done && t[i] >= ends[i][end_idx[i]] {
                if end_idx[i] + 1 == ends[i].len() {
                    state[i] = LaneState::Done;
                    out[i] = Ok(stats[i]);
                    continue;
                }
                end_idx[i] += 1;
                seg[i] += 1;
                state[i] = LaneState::Fresh;
            }
            if state[i] == LaneState::Fresh {
                f(i, seg[i], t[i], ys[i].as_ref(), k[i][0].as_mut()); // the input's slope changed
                stats[i].evaluations += 1;
                state[i] = LaneState::Running;
            }
            if state[i] == LaneState::Running {
                any = true;
                let end = ends[i][end_idx[i]];
                last[i] = end - (t[i] + h[i]) < 1e-3 * h[i];
                step[i] = if last[i] { end - t[i] } else { h[i] };
            }
        }
        if !any {
            return out;
        }
        for (s, a) in [
            (1usize, &A2[..]),
            (2, &A3[..]),
            (3, &A4[..]),
            (4, &A5[..]),
            (5, &A6[..]),
        ] {
            for i in 0..L {
                if state[i] == LaneState::Running {
                    combine(tmp[i].as_mut(), ys[i].as_ref(), step[i], a, &k[i]);
                    f(
                        i,
                        seg[i],
                        t[i] + C[s] * step[i],
                        tmp[i].as_ref(),
                        k[i][s].as_mut(),
                    );
                }
            }
        }
        for i in 0..L {
            if state[i] == LaneState::Running {
                combine(y_new[i].as_mut(), ys[i].as_ref(), step[i], &B, &k[i]);
                f(
                    i,
                    seg[i],
                    t[i] + step[i],
                    y_new[i].as_ref(),
                    k[i][6].as_mut(),
                );
            }
        }
        for i in 0..L {
            if state[i] != LaneState::Running {
                continue;
            }
            stats[i].evaluations += 6;
            let (yv, ynv, o) = (ys[i].as_ref(), y_new[i].as_ref(), opts[i]);
            let mut err2 = 0.0;
            for c in 0..yv.len() {
                if o.scale[c].is_finite() {
                    let mut e = 0.0;
                    for (j, ej) in E.iter().enumerate() {
                        e += ej * k[i][j].as_ref()[c];
                    }
                    let tol = o.atol * o.scale[c] + o.rtol * yv[c].abs().max(ynv[c].abs());
                    err2 += (step[i] * e / tol).powi(2);
                }
            }
            let err = (err2 / in_norm[i]).sqrt(); // NaN when the state blew up: rejected below
            if err <= 1.0 {
                t[i] = if last[i] {
                    ends[i][end_idx[i]]
                } else {
                    t[i] + step[i]
                };
                ys[i].as_mut().copy_from_slice(y_new[i].as_ref());
                k[i].swap(0, 6); // first same as last
                stats[i].accepted += 1;
                if !observe(i, t[i], ys[i].as_ref()) {
                    state[i] = LaneState::Done;
                    out[i] = Ok(stats[i]);
                    continue;
                }
                let grow = if err == 0.0 {
                    5.0
                } else {
                    (0.9 * err.powf(-0.2)).clamp(0.2, 5.0)
                };
                if !last[i] || grow < 1.0 {
                    h[i] = (step[i] * grow).min(o.h_max);
                }
            } else {
                stats[i].rejected += 1;
                let shrink = if err.is_finite() {
                    (0.9 * err.powf(-0.2)).clamp(0.1, 0.9)
                } else {
                    0.1
                };
                h[i] = step[i] * shrink;
                if h[i] < o.h_min {
                    state[i] = LaneState::Done;
                    out[i] = Err((t[i], format!("step size fell below {:.1e} s", o.h_min)));
                }
            }
        }
    }
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
        Dopri5Options {
            rtol,
            atol: rtol,
            scale: vec![1.0; 2],
            h_init: 1e-3,
            h_min: 1e-12,
            h_max: 1.0,
        }
    }

    #[test]
    fn harmonic_oscillator_meets_tolerance() {
        let mut y = [1.0, 0.0];
        let s = integrate(
            |_, _, y: &[f64], dy: &mut [f64]| {
                dy[0] = y[1];
                dy[1] = -y[0];
            },
            0.0,
            10.0,
            &[],
            &mut y,
            &opts(1e-9),
            |_, _| true,
        )
        .unwrap();
        assert!((y[0] - 10f64.cos()).abs() < 1e-7, "{}", y[0]);
        assert!(s.accepted > 10 && s.accepted < 2000);
    }

    #[test]
    fn lanes_agree_bitwise_with_single_runs() {
        let o = Dopri5Options {
            scale: vec![1.0; 2],
            ..opts(1e-8)
        };
        let rhs = |w: f64| {
            move |_seg: usize, _t: f64, y: &[f64], dy: &mut [f64]| {
                dy[0] = y[1];
                dy[1] = -w * w * y[0].sin();
            }
        };
        let single = |w: f64, t1: f64| {
            let mut y = [1.0, 0.0];
            integrate(rhs(w), 0.0, t1, &[0.0, 0.3], &mut y, &o, |_, _| true).unwrap();
            y
        };
        let mut ys = [[1.0, 0.0]; 3];
        let ws = [1.0, 3.0, 0.5];
        let t1s = [2.0, 5.0, 1.0];
        let r = integrate_lanes(
            |lane: usize, seg, t, y: &[f64], dy: &mut [f64]| rhs(ws[lane])(seg, t, y, dy),
            [0.0; 3],
            t1s,
            [&[0.0, 0.3][..]; 3],
            &mut ys,
            [&o; 3],
            |_, _, _| true,
        );
        for i in 0..3 {
            assert!(r[i].is_ok());
            assert_eq!(ys[i], single(ws[i], t1s[i]));
        }
    }

    #[test]
    fn lands_exactly_on_stops_and_switches_segments() {
        // dy/dt = slope of the segment: 1 on [0,1), -2 on [1,3)
        let mut y = [0.0];
        let mut times = vec![];
        let o = Dopri5Options {
            scale: vec![1.0],
            ..opts(1e-10)
        };
        integrate(
            |seg, _, _: &[f64], dy: &mut [f64]| dy[0] = if seg == 0 { 1.0 } else { -2.0 },
            0.0,
            3.0,
            &[0.0, 1.0, 3.0],
            &mut y,
            &o,
            |t, _| {
                times.push(t);
                true
            },
        )
        .unwrap();
        assert!(times.contains(&1.0));
        assert!((y[0] - (1.0 - 4.0)).abs() < 1e-12, "{}", y[0]);
    }
}

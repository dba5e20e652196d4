//! Leuven friction on the main body (MODEL.md eqs. 6-9): a Stribeck curve S(v) for sliding and a
//! Bouc-Wen presliding force Fh driven by the asperity deformation g.

use crate::numbers::lane_real::Lanewise;
use crate::numbers::real::{Mask, Real};
use crate::physics::params::Params;

/// Leuven friction constants, precomputed once per run (`T` = f64, or a dual number when
/// derivatives with respect to them are asked for).
#[derive(Clone, Copy, Debug)]
pub struct Leuven<T: Real = f64> {
    fc: T,
    fs_minus_fc: T,
    inv_vs: T,
    delta: T,
    n: T,
    a: T,
    b: T,
    c: T,
    sigma1: T,
    sigma2: T,
    /// Direction asymmetry: Fc, Fs scaled by (1 + eps sgn v) (0 for the paper's model).
    eps: T,
    /// no Stribeck peak and no derivative through one: the exp is skipped (per lane)
    no_peak: T::Mask,
    symmetric: T::Mask,
    delta_is_two: T::Mask,
    n_is_one: T::Mask,
}

impl<T: Real> Leuven<T> {
    /// `normal_force` is passed explicitly so that effects (an incline) can change it.
    pub fn new(p: &Params<T>, normal_force: T, eps: T) -> Self {
        let fs_minus_fc = (p.mu_s - p.mu_k) * normal_force;
        Leuven {
            fc: p.mu_k * normal_force,
            fs_minus_fc,
            inv_vs: T::one() / p.stribeck_velocity,
            delta: p.stribeck_exponent,
            n: p.fric_n,
            a: p.fric_alpha,
            b: p.fric_beta,
            c: p.fric_gamma,
            sigma1: p.sigma1,
            sigma2: p.sigma2,
            eps,
            no_peak: fs_minus_fc.is_exactly(0.0),
            symmetric: eps.is_exactly(0.0),
            delta_is_two: p.stribeck_exponent.is_exactly(2.0),
            n_is_one: p.fric_n.is_exactly(1.0),
        }
    }

    /// Stribeck curve S(v) = Fc + (Fs - Fc) exp(-(|v|/vs)^delta) [N], times (1 + eps sgn v).
    #[inline(always)]
    pub fn stribeck(&self, v: T) -> T {
        // no Stribeck peak (mu_s = mu_k): skip the exp (lanes: when no lane has a peak). Branches
        // here are plain `if`s and selects, not closures (see `Real::select`).
        let s = if self.no_peak.all() {
            self.fc
        } else {
            T::select(self.no_peak, self.fc, self.stribeck_curve(v))
        };
        if self.symmetric.all() {
            s
        } else {
            T::select(self.symmetric, s, s * (self.eps * v.sign0() + 1.0))
        }
    }

    /// Fc + (Fs - Fc) exp(-(|v|/vs)^delta) [N], the symmetric curve with its peak.
    #[inline(always)]
    fn stribeck_curve(&self, v: T) -> T {
        let x = v.abs() * self.inv_vs;
        // (|v|/vs)^2 as a product: powf would be the most expensive call in the step
        let square = x * x;
        let e = if self.delta_is_two.all() {
            square
        } else {
            T::select(self.delta_is_two, square, x.pow(self.delta))
        };
        self.fc + self.fs_minus_fc * (-e).exp()
    }

    /// (dg/dt [m/s], dFh/dt [N/s]) at main-body velocity `v` [m/s] and presliding force `fh` [N].
    #[inline(always)]
    pub fn rates(&self, v: T, fh: T) -> (T, T) {
        let ratio = fh / self.stribeck(v);
        // eq. 6 written with |v| so that v = 0 needs no 0/0; for n = 1, sgn(Fh)|Fh/S| = Fh/S
        let linear = v - v.abs() * ratio;
        let gdot = if self.n_is_one.all() {
            linear
        } else {
            T::select(
                self.n_is_one,
                linear,
                v - v.abs() * fh.sign0() * ratio.abs().pow(self.n),
            )
        };
        let fhdot = self.a * gdot - self.b * gdot.abs() * fh - self.c * gdot * fh.abs();
        (gdot, fhdot)
    }

    /// dS/dv [N s/m], the Stribeck curve's slope (0 at v = 0, where the curve is flat for
    /// delta > 1; the one-sided slope is taken for delta <= 1).
    #[inline(always)]
    pub fn stribeck_slope(&self, v: T) -> T {
        T::choose(self.no_peak.or(v.equals(0.0)), T::zero, || {
            let x = v.abs() * self.inv_vs;
            let e = T::choose(self.delta_is_two, || x * x, || x.pow(self.delta));
            let de = T::choose(self.delta_is_two, || x * 2.0, || self.delta * x.pow(self.delta - 1.0));
            let ds = -self.fs_minus_fc * (-e).exp() * de * self.inv_vs * v.sign0();
            ds * (self.eps * v.sign0() + 1.0)
        })
    }

    /// The rates of [`Leuven::rates`] and their partial derivatives, for implicit integrators:
    /// `[dg/dt, dFh/dt, d(dg/dt)/dv, d(dg/dt)/dFh, d(dFh/dt)/dv, d(dFh/dt)/dFh]` (units follow
    /// from [m/s], [N/s] over [m/s], [N]). Exact away from the kinks at v = 0 and dg/dt = 0.
    #[inline(always)]
    pub fn rate_partials(&self, v: T, fh: T) -> [T; 6] {
        let (gdot, fhdot) = self.rates(v, fh);
        let s = self.stribeck(v);
        let ratio = fh / s;
        // gdot = v - |v| sgn(Fh) |Fh/S|^n
        let pow_n = T::choose(self.n_is_one, || ratio.abs(), || ratio.abs().pow(self.n));
        let pow_n1 = T::choose(self.n_is_one, T::one, || self.n * ratio.abs().pow(self.n - 1.0));
        let dg_dfh = -v.abs() * pow_n1 / s;
        let dg_dv = -pow_n * (v.sign0() * fh.sign0()) + 1.0 + v.abs() * pow_n1 * fh * self.stribeck_slope(v) / (s * s);
        // dFh/dt = a gdot - b |gdot| Fh - c gdot |Fh|
        let outer = self.a - self.b * gdot.sign0() * fh - self.c * fh.abs();
        let dfh_dv = outer * dg_dv;
        let dfh_dfh = outer * dg_dfh - self.b * gdot.abs() - self.c * gdot * fh.sign0();
        [gdot, fhdot, dg_dv, dg_dfh, dfh_dv, dfh_dfh]
    }

    /// Friction force Ff = Fh + sigma2 v + sigma1 dg/dt [N], acting against the main body.
    /// dg/dt is known last (it waits on the Stribeck exp and a division), so it is added last.
    #[inline(always)]
    pub fn force(&self, v: T, fh: T, gdot: T) -> T {
        (fh + self.sigma2 * v) + self.sigma1 * gdot
    }
}

impl<S: Real, T: Real + Lanewise<S>> Lanewise<Leuven<S>> for Leuven<T>
where
    T::Mask: Lanewise<S::Mask>,
{
    fn splat(m: &Leuven<S>) -> Self {
        Leuven {
            fc: Lanewise::splat(&m.fc),
            fs_minus_fc: Lanewise::splat(&m.fs_minus_fc),
            inv_vs: Lanewise::splat(&m.inv_vs),
            delta: Lanewise::splat(&m.delta),
            n: Lanewise::splat(&m.n),
            a: Lanewise::splat(&m.a),
            b: Lanewise::splat(&m.b),
            c: Lanewise::splat(&m.c),
            sigma1: Lanewise::splat(&m.sigma1),
            sigma2: Lanewise::splat(&m.sigma2),
            eps: Lanewise::splat(&m.eps),
            no_peak: Lanewise::splat(&m.no_peak),
            symmetric: Lanewise::splat(&m.symmetric),
            delta_is_two: Lanewise::splat(&m.delta_is_two),
            n_is_one: Lanewise::splat(&m.n_is_one),
        }
    }
    fn set_lane(&mut self, i: usize, m: &Leuven<S>) {
        self.fc.set_lane(i, &m.fc);
        self.fs_minus_fc.set_lane(i, &m.fs_minus_fc);
        self.inv_vs.set_lane(i, &m.inv_vs);
        self.delta.set_lane(i, &m.delta);
        self.n.set_lane(i, &m.n);
        self.a.set_lane(i, &m.a);
        self.b.set_lane(i, &m.b);
        self.c.set_lane(i, &m.c);
        self.sigma1.set_lane(i, &m.sigma1);
        self.sigma2.set_lane(i, &m.sigma2);
        self.eps.set_lane(i, &m.eps);
        self.no_peak.set_lane(i, &m.no_peak);
        self.symmetric.set_lane(i, &m.symmetric);
        self.delta_is_two.set_lane(i, &m.delta_is_two);
        self.n_is_one.set_lane(i, &m.n_is_one);
    }
}

impl Leuven {
    /// The constants in the order the GPU kernel reads them (`gpu/kernel.rs`): Fc, Fs - Fc, 1/vs,
    /// delta, n, a, b, c, sigma1, sigma2, eps [SI].
    pub fn constants(&self) -> [f64; 11] {
        [
            self.fc,
            self.fs_minus_fc,
            self.inv_vs,
            self.delta,
            self.n,
            self.a,
            self.b,
            self.c,
            self.sigma1,
            self.sigma2,
            self.eps,
        ]
    }

    /// Rough stiffness |d(dFh/dt)/dFh| during sliding at speed |v| [1/s], for step-size hints.
    pub fn sliding_stiffness(&self, v: f64) -> f64 {
        let s = self.stribeck(v).max(1e-300);
        v.abs() * (self.a * self.n / s + self.b + self.c.abs())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stribeck_curve_runs_from_static_to_coulomb() {
        let p = Params::paper();
        let f = Leuven::new(&p, p.normal_force, 0.0);
        assert!((f.stribeck(0.0) - 0.6 * p.normal_force).abs() < 1e-12);
        assert!((f.stribeck(1.0) - 0.5 * p.normal_force).abs() < 1e-12);
        let at_vs = 0.5 * p.normal_force + 0.1 * p.normal_force * (-1.0f64).exp();
        assert!((f.stribeck(-1e-3) - at_vs).abs() < 1e-12);
    }

    #[test]
    fn presliding_is_elastic_at_zero_force() {
        let p = Params::paper();
        let f = Leuven::new(&p, p.normal_force, 0.0);
        let (gdot, fhdot) = f.rates(1e-6, 0.0);
        assert_eq!(gdot, 1e-6);
        assert_eq!(fhdot, p.fric_alpha * 1e-6);
        assert_eq!(f.rates(0.0, 1.3), (0.0, 0.0));
    }

    #[test]
    fn sliding_force_saturates_at_stribeck_level() {
        // At Fh = S(v) with the same sign as v, the asperities stop deforming.
        let p = Params::paper();
        let f = Leuven::new(&p, p.normal_force, 0.0);
        let v = 2e-3;
        let (gdot, _) = f.rates(v, f.stribeck(v));
        assert!(gdot.abs() < 1e-15);
    }

    #[test]
    fn rate_partials_match_finite_differences() {
        let p = Params::paper();
        for (eps, n, delta) in [(0.0, 1.0, 2.0), (0.1, 1.7, 0.8), (-0.05, 1.0, 1.3)] {
            let mut q = p;
            q.fric_n = n;
            q.stribeck_exponent = delta;
            let f = Leuven::new(&q, q.normal_force, eps);
            for (v, fh) in [(2e-3, 0.3), (-4e-4, -0.9), (1e-5, -0.2), (-3e-3, 1.1)] {
                let d = f.rate_partials(v, fh);
                let (hv, hf) = (1e-7 * v.abs(), 1e-7 * fh.abs());
                let fd = |x: (f64, f64), y: (f64, f64), h: f64| ((x.0 - y.0) / (2.0 * h), (x.1 - y.1) / (2.0 * h));
                let dv = fd(f.rates(v + hv, fh), f.rates(v - hv, fh), hv);
                let df = fd(f.rates(v, fh + hf), f.rates(v, fh - hf), hf);
                for (a, b) in [(d[2], dv.0), (d[4], dv.1), (d[3], df.0), (d[5], df.1)] {
                    assert!((a - b).abs() <= 1e-6 * b.abs() + 1e-12, "{a} {b} at {v} {fh}");
                }
            }
        }
    }

    #[test]
    fn asymmetry_scales_levels_by_direction() {
        let p = Params::paper();
        let f = Leuven::new(&p, p.normal_force, 0.1);
        assert!((f.stribeck(1.0) / f.stribeck(-1.0) - 1.1 / 0.9).abs() < 1e-12);
    }
}

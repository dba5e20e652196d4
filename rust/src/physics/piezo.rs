//! Piezo element force with Bouc-Wen hysteresis (MODEL.md eqs. 14, 15).

use crate::error::InputError;
use crate::numbers::lane_real::Lanewise;
use crate::numbers::real::Real;
use crate::numbers::scalar::Scalar;

/// Bouc-Wen piezo hysteresis constants.
#[derive(Clone, Copy, Debug)]
pub struct PiezoHysteresis<T = f64> {
    /// ap d33 [m/V]
    ap_d33: T,
    /// bp [1/V]
    bp: T,
    /// cp [1/V]
    cp: T,
}

impl<T: Real> PiezoHysteresis<T> {
    pub fn new(ap: T, bp: T, cp: T, d33: T) -> Self {
        PiezoHysteresis {
            ap_d33: ap * d33,
            bp,
            cp,
        }
    }

    /// dh/dt = ap d33 dV/dt - bp |dV/dt| h - cp dV/dt |h| [m/s], for dV/dt in V/s and h in m.
    #[inline(always)]
    pub fn rate(&self, dv: T, h: T) -> T {
        self.ap_d33 * dv - self.bp * dv.abs() * h - self.cp * dv * h.abs()
    }

    /// (d(dh/dt)/d(dV/dt) [m/V], d(dh/dt)/dh [1/s]) of [`PiezoHysteresis::rate`].
    #[inline(always)]
    pub fn rate_partials(&self, dv: T, h: T) -> (T, T) {
        (
            self.ap_d33 - self.bp * dv.sign0() * h - self.cp * h.abs(),
            -self.bp * dv.abs() - self.cp * dv * h.sign0(),
        )
    }
}

impl<S, T: Lanewise<S>> Lanewise<PiezoHysteresis<S>> for PiezoHysteresis<T> {
    fn splat(h: &PiezoHysteresis<S>) -> Self {
        PiezoHysteresis {
            ap_d33: Lanewise::splat(&h.ap_d33),
            bp: Lanewise::splat(&h.bp),
            cp: Lanewise::splat(&h.cp),
        }
    }
    fn set_lane(&mut self, i: usize, h: &PiezoHysteresis<S>) {
        self.ap_d33.set_lane(i, &h.ap_d33);
        self.bp.set_lane(i, &h.bp);
        self.cp.set_lane(i, &h.cp);
    }
}

impl PiezoHysteresis {
    /// (ap d33 [m/V], bp [1/V], cp [1/V]), as the GPU kernel reads them.
    pub fn constants(&self) -> [f64; 3] {
        [self.ap_d33, self.bp, self.cp]
    }
}

/// The IDM's actuation: the piezo element between the main body (node 0) and the weight (the
/// last node) pushes them apart with the piezo force.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PiezoElement;

impl crate::physics::actuation::Actuation for PiezoElement {
    fn check(&self, _effects: &crate::physics::effects::Effects, _piezo_hysteresis: bool) -> Result<(), InputError> {
        Ok(())
    }

    /// The PE mass rests on the guide with both bodies (MODEL.md's normal force).
    fn supported_mass<T: Scalar>(&self, p: &crate::physics::params::Params<T>) -> T {
        p.m1 + p.m2 + p.pe_mass()
    }

    #[inline(always)]
    fn forces<T: Real>(&self, fp: T, _u: T, _du: T, _x: T, _v: T) -> (T, T) {
        (fp, -fp)
    }

    #[inline(always)]
    fn force_partials<T: Scalar>(&self, _u: T, _x: T, _v: T) -> [f64; 5] {
        [1.0, -1.0, 0.0, 0.0, 0.0]
    }

    /// The piezo force's work on both ends.
    #[inline(always)]
    fn power<T: Real>(&self, f_main: T, v_main: T, v_last: T) -> T {
        f_main * (v_main - v_last)
    }

    #[inline(always)]
    fn power_partials<T: Scalar>(&self, f_main: T, v_main: T, v_last: T) -> [T; 3] {
        [v_main - v_last, f_main, -f_main]
    }
}

/// Fp = kp (d33 V + xc - h) [N]: pushes the main body forward and the weight back. `xc` [m] is
/// an extra free extension (creep; 0 in the paper's model).
#[inline(always)]
pub fn piezo_force<T: Real>(kp: T, d33: T, voltage: T, xc: T, h: T) -> T {
    kp * (d33 * voltage + xc - h)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hysteresis_is_rate_independent() {
        // Bouc-Wen is rate-independent: h after a voltage ramp depends on the path in V, not time.
        let hyst = PiezoHysteresis::new(0.4297, 3.438e-2, -2.865e-3, 1.24e-7);
        let integrate = |dvdt: f64| {
            let (mut h, steps) = (0.0, 100_000);
            let dt = 80.0 / dvdt / steps as f64;
            for _ in 0..steps {
                h += dt * hyst.rate(dvdt, h);
            }
            h
        };
        let (slow, fast) = (integrate(1e3), integrate(1e6));
        assert!((slow - fast).abs() < 1e-12 * slow.abs().max(1e-9), "{slow} {fast}");
        assert!(slow > 0.0 && slow < 0.4297 * 1.24e-7 * 80.0);
    }

    #[test]
    fn force_is_stiffness_times_free_stroke() {
        assert_eq!(piezo_force(2.0, 1e-7, 10.0, 0.0, 0.0), 2e-6);
        assert_eq!(piezo_force(2.0, 1e-7, 10.0, 1e-6, 1e-6), 2e-6);
    }
}

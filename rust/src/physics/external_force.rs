//! A sampled external force on one body: a second input beside the voltage, piecewise linear
//! in time through its samples (knots), held at the first and last sample outside them. The
//! driver lands on its knots as on the voltage's breakpoints (RK4: they must fall on step
//! boundaries), so within a step the force is one linear piece. Its knot values can be seeded
//! like parameters (`sensitivity::Seed::ForceKnot`): the derivative of a run with respect to
//! the force at each knot, which is what infers an unknown force from a recording.

use crate::error::InputError;
use crate::numbers::lane_real::Lanewise;
use crate::numbers::real::Real;
use crate::physics::waveform::PiecewiseLinear;

/// Which body the force acts on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Body {
    /// the main body (node 0, on the friction guide)
    Main,
    /// the weight (the last node)
    Weight,
}

impl Body {
    pub fn from_name(name: &str) -> Result<Self, InputError> {
        match name {
            "main" => Ok(Body::Main),
            "weight" => Ok(Body::Weight),
            _ => Err(crate::input!(
                "external force body '{name}': use 'main' (the main body) or 'weight'"
            )),
        }
    }
}

/// The force [N] on `body` at the knot times [s] (`knots`: the plain samples, which fix the
/// times and the driver's stops) with values `values` (as the physics reads them: dual numbers
/// where knots are seeded).
#[derive(Clone, Debug)]
pub struct ExternalForce<T = f64> {
    pub body: Body,
    pub knots: PiecewiseLinear,
    pub values: Vec<T>,
}

impl ExternalForce {
    /// The force on `body` through samples `(t [s], f [N])`: at least two, times increasing,
    /// every value finite (the message names the sample that is not).
    pub fn new(body: Body, t: Vec<f64>, f: Vec<f64>) -> Result<Self, InputError> {
        if t.len() < 2 {
            return Err(crate::input!(
                "external force: give at least two samples, got {}",
                t.len()
            ));
        }
        let knots = PiecewiseLinear::new(t, f.clone()).map_err(|e| format!("external force: {e}"))?;
        Ok(ExternalForce { body, knots, values: f })
    }

    /// The same force with every value read as `lift(k, value)` (a dual number seeded for the
    /// knots whose derivatives are asked for).
    pub fn lift<T>(&self, lift: impl Fn(usize, f64) -> T) -> ExternalForce<T> {
        ExternalForce {
            body: self.body,
            knots: self.knots.clone(),
            values: self.values.iter().enumerate().map(|(k, v)| lift(k, *v)).collect(),
        }
    }

    pub fn len(&self) -> usize {
        self.values.len()
    }

    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }
}

impl<S, T: Lanewise<S>> Lanewise<ExternalForce<S>> for ExternalForce<T> {
    fn splat(x: &ExternalForce<S>) -> Self {
        ExternalForce {
            body: x.body,
            knots: x.knots.clone(),
            values: Lanewise::splat(&x.values),
        }
    }
    fn set_lane(&mut self, i: usize, x: &ExternalForce<S>) {
        // one body and one set of knot times in every lane (the lane gate's shape)
        self.values.set_lane(i, &x.values);
    }
}

impl<T: Real> ExternalForce<T> {
    /// The force [N] at time `t` [s] and its slope [N/s] there (0 outside the samples). The
    /// force is continuous, so at a knot either neighbouring piece gives the same value.
    #[inline]
    pub fn at(&self, t: T::Value) -> (T, T) {
        T::interpolate(&self.values, self.knots.times(), t)
    }

    /// The first knot after `t` [s] (infinity past the last): an adaptive step ends there.
    pub fn next_knot(&self, t: f64) -> f64 {
        let ts = self.knots.times();
        let j = ts.partition_point(|&x| x <= t * (1.0 + 1e-14) + 1e-18);
        ts.get(j).copied().unwrap_or(f64::INFINITY)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_force_is_linear_between_samples_and_held_outside() {
        let f = ExternalForce::new(Body::Main, vec![0.0, 1.0, 3.0], vec![0.0, 2.0, -2.0]).unwrap();
        assert_eq!(f.at(0.5), (1.0, 2.0));
        assert_eq!(f.at(2.0), (0.0, -2.0));
        assert_eq!(f.at(1.0).0, 2.0);
        assert_eq!(f.at(-1.0), (0.0, 0.0));
        assert_eq!(f.at(5.0), (-2.0, 0.0));
        assert_eq!(f.next_knot(0.0), 1.0);
        assert_eq!(f.next_knot(1.0), 3.0);
        assert_eq!(f.next_knot(3.0), f64::INFINITY);
    }

    #[test]
    fn bad_samples_are_refused_by_name() {
        assert!(ExternalForce::new(Body::Main, vec![0.0], vec![1.0])
            .unwrap_err()
            .contains("two samples"));
        assert!(ExternalForce::new(Body::Main, vec![0.0, 1.0], vec![1.0, f64::NAN])
            .unwrap_err()
            .contains("external force"));
        assert!(Body::from_name("base").unwrap_err().contains("'main'"));
    }
}

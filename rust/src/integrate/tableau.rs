//! Each explicit method's coefficients, written once and read by every driver of it: the scalar
//! and lane steppers (`integrate/rk4.rs`, `integrate/dopri5.rs`), the vector lanes
//! (`lanes/rk4.rs`, `lanes/dopri5.rs`), the derivative pass (`sensitivity/`) and the GPU
//! kernel, whose `#define`s are generated from these constants (`gpu/kernel.rs`).
//!
//! RK4's update is a function, not a weight vector: the CPU drivers' results are bitwise equal
//! to one another only if each forms the sum in the same order, k1 + 2 (k2 + k3) + k4, then
//! times dt / 6.

use std::ops::{Add, Mul};

/// RK4's stage offsets as fractions of the step.
pub const RK4_NODES: [f64; 4] = [0.0, 0.5, 0.5, 1.0];
/// RK4's weight of its two middle stages relative to the outer two.
pub const RK4_MIDDLE_WEIGHT: f64 = 2.0;
/// RK4's weights' common denominator: y += (k1 + 2 (k2 + k3) + k4) dt / 6.
pub const RK4_DENOMINATOR: f64 = 6.0;

/// RK4's stage sum k1 + 2 (k2 + k3) + k4, in the order every driver forms it.
#[inline(always)]
pub fn rk4_sum<T: Copy + Add<Output = T> + Mul<f64, Output = T>>(k1: T, k2: T, k3: T, k4: T) -> T {
    k1 + (k2 + k3) * RK4_MIDDLE_WEIGHT + k4
}

/// dt / 6, the factor of [`rk4_sum`] in an RK4 step of `dt` [s].
#[inline(always)]
pub fn rk4_factor(dt: f64) -> f64 {
    dt / RK4_DENOMINATOR
}

/// Dormand-Prince 5(4): stage offsets as fractions of the step.
pub const DP5_C: [f64; 7] = [0.0, 1.0 / 5.0, 3.0 / 10.0, 4.0 / 5.0, 8.0 / 9.0, 1.0, 1.0];
/// Dormand-Prince 5(4): the rows of the stage matrix (stage 2 to 6; stage 7 is [`DP5_B`]).
pub const DP5_A2: [f64; 1] = [1.0 / 5.0];
pub const DP5_A3: [f64; 2] = [3.0 / 40.0, 9.0 / 40.0];
pub const DP5_A4: [f64; 3] = [44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0];
pub const DP5_A5: [f64; 4] = [19372.0 / 6561.0, -25360.0 / 2187.0, 64448.0 / 6561.0, -212.0 / 729.0];
pub const DP5_A6: [f64; 5] = [
    9017.0 / 3168.0,
    -355.0 / 33.0,
    46732.0 / 5247.0,
    49.0 / 176.0,
    -5103.0 / 18656.0,
];
/// Dormand-Prince 5(4): fifth-order weights (also the last stage's coefficients: first same as
/// last).
pub const DP5_B: [f64; 6] = [
    35.0 / 384.0,
    0.0,
    500.0 / 1113.0,
    125.0 / 192.0,
    -2187.0 / 6784.0,
    11.0 / 84.0,
];
/// Dormand-Prince 5(4): the fifth- less the fourth-order weights (the error estimate).
pub const DP5_E: [f64; 7] = [
    71.0 / 57600.0,
    0.0,
    -71.0 / 16695.0,
    71.0 / 1920.0,
    -17253.0 / 339200.0,
    22.0 / 525.0,
    -1.0 / 40.0,
];

/// The tableaus as C `#define`s for the GPU kernel (`IDM_RK4_*`, `IDM_DP5_*`), each value
/// printed so that it parses back to the same double.
pub fn c_defines() -> String {
    let mut h = String::new();
    let mut put = |name: String, v: f64| h += &format!("#define {name} ({v:?})\n");
    for (i, c) in RK4_NODES.iter().enumerate() {
        put(format!("IDM_RK4_C{}", i + 1), *c);
    }
    put("IDM_RK4_MIDDLE_WEIGHT".into(), RK4_MIDDLE_WEIGHT);
    put("IDM_RK4_DENOMINATOR".into(), RK4_DENOMINATOR);
    for (i, c) in DP5_C.iter().enumerate() {
        put(format!("IDM_DP5_C{}", i + 1), *c);
    }
    let rows: [&[f64]; 5] = [&DP5_A2, &DP5_A3, &DP5_A4, &DP5_A5, &DP5_A6];
    for (r, row) in rows.iter().enumerate() {
        for (j, a) in row.iter().enumerate() {
            put(format!("IDM_DP5_A{}{}", r + 2, j + 1), *a);
        }
    }
    for (i, b) in DP5_B.iter().enumerate() {
        put(format!("IDM_DP5_B{}", i + 1), *b);
    }
    for (i, e) in DP5_E.iter().enumerate() {
        put(format!("IDM_DP5_E{}", i + 1), *e);
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_weights_are_consistent_and_the_c_defines_parse_back_to_the_same_doubles() {
        // RK4: weights sum to one; each Dormand-Prince row sums to its node; both weight sets
        // (fifth order, and fifth less the error) sum to one
        assert_eq!((2.0 + 2.0 * RK4_MIDDLE_WEIGHT) / RK4_DENOMINATOR, 1.0);
        let rows: [&[f64]; 5] = [&DP5_A2, &DP5_A3, &DP5_A4, &DP5_A5, &DP5_A6];
        for (r, row) in rows.iter().enumerate() {
            assert!((row.iter().sum::<f64>() - DP5_C[r + 1]).abs() < 1e-14, "row {}", r + 2);
        }
        assert!((DP5_B.iter().sum::<f64>() - 1.0).abs() < 1e-14);
        let fourth: f64 = DP5_B
            .iter()
            .chain([0.0].iter())
            .zip(DP5_E.iter())
            .map(|(b, e)| b - e)
            .sum();
        assert!((fourth - 1.0).abs() < 1e-14);
        let h = c_defines();
        for line in h.lines() {
            let value = line.split_once(" (").unwrap().1.trim_end_matches(')');
            let name = line.split_whitespace().nth(1).unwrap();
            let v: f64 = value.parse().unwrap();
            let want = match name {
                "IDM_DP5_A53" => DP5_A5[2],
                "IDM_DP5_E5" => DP5_E[4],
                "IDM_RK4_C2" => 0.5,
                _ => continue,
            };
            assert_eq!(v.to_bits(), want.to_bits(), "{line}");
        }
        assert!(h.contains("#define IDM_DP5_A21 (0.2)\n") && h.contains("#define IDM_RK4_DENOMINATOR (6.0)\n"));
        assert_eq!(h.lines().count(), 4 + 2 + 7 + 15 + 6 + 7);
    }
}

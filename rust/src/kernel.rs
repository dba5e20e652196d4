//! The per-point constants of the GPU kernel (`python/idm_rs/gpu/idm_kernel.cu`), packed from
//! a [`Model`] in the one order the kernel reads them. The kernel's physics mirrors `model.rs`
//! for the models it supports (LPS or DPS up to `MAX_DOF` nodes, piezo hysteresis on or off,
//! no effects); the test suite compiles the same kernel source for the CPU and checks it
//! against this engine, so a change of the model that is not mirrored there fails a test.

use crate::model::Model;

/// Largest node count the kernel holds (DPS with 5 elements).
pub const MAX_DOF: usize = 6;
/// Scalars before the matrices: dof, kp, d33, 11 friction constants, hysteresis on, its 3
/// constants, the |Fh| bound, and the LPS frequency sqrt(kp (1/m1 + 1/m2)) [rad/s] that scales
/// velocities in the adaptive method's error norm (`Model::state_scales`).
pub const N_SCALARS: usize = 20;
/// Total constants per point: the scalars, M^-1 K and M^-1 C (MAX_DOF^2 each, row-major,
/// zero-padded), and the two force columns of M^-1 (MAX_DOF each).
pub const N_CONSTANTS: usize = N_SCALARS + 2 * MAX_DOF * MAX_DOF + 2 * MAX_DOF;

/// The kernel's constants for `model`, or why the kernel cannot run it.
pub fn kernel_constants(model: &Model) -> Result<Vec<f64>, String> {
    let n = model.layout.dof;
    if n > MAX_DOF {
        return Err(format!("the GPU kernel holds at most {MAX_DOF} nodes (DPS with {} elements); got {n}", MAX_DOF - 1));
    }
    if !model.is_plain() || model.effects != crate::effects::Effects::default() {
        return Err("the GPU kernel runs the paper's model only: switch every effect off (or use the CPU backend)".into());
    }
    if model.rig.is_some() {
        return Err("the GPU kernel runs the IDM, not a rig".into());
    }
    let mut c = vec![0.0; N_CONSTANTS];
    c[0] = n as f64;
    c[1] = model.kp;
    c[2] = model.d33;
    c[3..14].copy_from_slice(&model.friction.constants());
    if let Some(h) = model.hysteresis {
        c[14] = 1.0;
        c[15..18].copy_from_slice(&h.constants());
    }
    c[18] = model.presliding_bound();
    let p = &model.params;
    c[19] = (p.kp() * (1.0 / p.m1 + 1.0 / p.m2)).sqrt();
    let (mk, mc) = (N_SCALARS, N_SCALARS + MAX_DOF * MAX_DOF);
    let (m0, ml) = (N_SCALARS + 2 * MAX_DOF * MAX_DOF, N_SCALARS + 2 * MAX_DOF * MAX_DOF + MAX_DOF);
    for i in 0..n {
        for j in 0..n {
            c[mk + i * MAX_DOF + j] = model.mech.minv_k[i * n + j];
            c[mc + i * MAX_DOF + j] = model.mech.minv_c[i * n + j];
        }
        c[m0 + i] = model.mech.minv_main[i];
        c[ml + i] = model.mech.minv_weight[i];
    }
    Ok(c)
}

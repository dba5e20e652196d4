//! Where each quantity lives in the flat state vector: the nodes' positions and velocities,
//! the friction and hysteresis states, the lag effects' states and the accounting states.

use crate::physics::effects::{Effects, LAGS, N_LAGS};

/// Number of energy/impulse accounting states (see [`Layout::accounting`]).
pub const N_ACCOUNTING: usize = 7;

/// Where each quantity lives in the flat state vector.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Layout {
    /// nodes (node 0 main body, node dof-1 weight)
    pub dof: usize,
    /// positions q at 0..dof, velocities at dof..2 dof
    pub g: usize,
    pub fh: usize,
    pub h: usize,
    /// the state of each lag effect that is on, in the order of `effects::LAGS` (the PE voltage
    /// behind the amplifier, the creep extension, the sensor reading)
    pub lags: [Option<usize>; N_LAGS],
    /// start of [W_input, W_friction, W_damping, W_external, I_friction, I_rayleigh, I_external]:
    /// works [J] and impulses [N s] integrated with the state, for energy and momentum budgets
    pub accounting: Option<usize>,
    pub dim: usize,
}

/// Names and units of the accounting states, in layout order.
const ACCOUNTING_COMPONENTS: [(&str, &str); N_ACCOUNTING] = [
    ("w_input", "J"),
    ("w_friction", "J"),
    ("w_damping", "J"),
    ("w_external", "J"),
    ("i_friction", "N s"),
    ("i_rayleigh", "N s"),
    ("i_external", "N s"),
];

impl Layout {
    /// Name and unit of every state component, in order: `q0..` nodal displacements [m] (node 0
    /// the main body, the last the weight), `v0..` nodal velocities [m/s], `g` asperity
    /// deformation [m], `fh` presliding force [N], `h` piezo hysteresis [m], then the states of
    /// the lag effects that are on (`effects::LAGS`: `v_pe` PE voltage [V], `x_creep` creep
    /// extension [m], `x_sensor` sensor reading [m]) and the accounting states.
    pub fn components(&self) -> Vec<(String, &'static str)> {
        let mut c: Vec<(String, &'static str)> = Vec::with_capacity(self.dim);
        c.extend((0..self.dof).map(|i| (format!("q{i}"), "m")));
        c.extend((0..self.dof).map(|i| (format!("v{i}"), "m/s")));
        c.extend([("g".into(), "m"), ("fh".into(), "N"), ("h".into(), "m")]);
        for (slot, lag) in self.lags.iter().zip(LAGS) {
            if slot.is_some() {
                c.push((lag.state.into(), lag.unit));
            }
        }
        if self.accounting.is_some() {
            c.extend(ACCOUNTING_COMPONENTS.iter().map(|(n, u)| (n.to_string(), *u)));
        }
        c
    }

    pub(crate) fn new(dof: usize, e: &Effects, accounting: bool) -> Self {
        let mut next = 2 * dof + 3;
        let mut take = |on: bool, len: usize| {
            on.then(|| {
                next += len;
                next - len
            })
        };
        let lags = std::array::from_fn(|k| take(e.value_of(LAGS[k].tau).unwrap_or(0.0) > 0.0, 1));
        let accounting = take(accounting, N_ACCOUNTING);
        Layout {
            dof,
            g: 2 * dof,
            fh: 2 * dof + 1,
            h: 2 * dof + 2,
            lags,
            accounting,
            dim: next,
        }
    }
}

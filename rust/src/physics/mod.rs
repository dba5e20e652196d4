//! The physics of the IDM, each law in its own file and none aware of integrators: the parameters
//! and their declarations, the input voltage, Leuven friction, the piezo element, the mechanisms
//! (LPS / DPS structures, the friction rig) behind the [`actuation::Actuation`] trait, the
//! optional effects (the library force among them, its terms one by one for discovery) and a
//! sampled external force.

pub mod actuation;
pub mod declare;
pub mod effects;
pub mod external_force;
pub mod friction;
pub mod library_columns;
pub mod mechanics;
pub mod params;
pub mod piezo;
pub mod rig;
pub mod waveform;

//! The sizes a model may have (the fixed capacities of the runtime's stack arrays), shared by the
//! model and its effects.

/// Most joints a model may have.
pub const MAX_JOINTS: usize = 7;
/// Largest task-space dimension (3-D position).
pub const MAX_TASK_DIM: usize = 3;
/// Most integration steps a model may ask for.
pub const MAX_STEPS: u16 = 64;
/// Highest harmonic or power a field expansion may use on one axis ([`crate::FieldExpansion`]).
pub const MAX_EXPANSION_ORDER: u8 = 63;
/// Most basis functions a field expansion may have per field (joint and task each).
pub const MAX_EXPANSION_FEATURES: u32 = 65_535;

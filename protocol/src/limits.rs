//! The sizes a model may have (the fixed capacities of the runtime's stack arrays), shared by the
//! model and its effects.

/// Most joints a model may have: 7 by default (an industrial arm with a linear track), 16 with the
/// feature `long-chains` (a humanoid's torso and arm). The blob format does not depend on it; a
/// runtime's stack arrays do (a query's 3-tensors hold MAX_JOINTS³ values): a controller for a
/// short arm keeps the small build. A blob with more joints than a build holds is refused with
/// [`crate::DecodeError::TooManyJoints`].
#[cfg(not(feature = "long-chains"))]
pub const MAX_JOINTS: usize = 7;
/// Most joints a model may have (feature `long-chains`; 7 without it).
#[cfg(feature = "long-chains")]
pub const MAX_JOINTS: usize = 16;
/// Most joints any build holds (with the feature `long-chains`): the trainer's and the model
/// file's limit.
pub const MAX_JOINTS_ANY_BUILD: usize = 16;
/// Largest task-space dimension (3-D position).
pub const MAX_TASK_DIM: usize = 3;
/// Most integration steps a model may ask for.
pub const MAX_STEPS: u16 = 64;
/// Highest harmonic or power a field expansion may use on one axis ([`crate::FieldExpansion`]).
pub const MAX_EXPANSION_ORDER: u8 = 63;
/// Most basis functions a field expansion may have per field (joint and task each).
pub const MAX_EXPANSION_FEATURES: u32 = 65_535;
/// Most tool points (measured points per pose) a DH chain may name (format 6).
pub const MAX_TOOL_POINTS: usize = 4;
/// Largest magnitude of a tool point's coordinate, in the model's length unit (1000 km in mm):
/// anything larger is not a lever on an arm, and would overflow the kinematics' squares in f32.
pub const MAX_TOOL_POINT_COORDINATE: f64 = 1e9;
/// Largest departure of a base or tool rotation from orthonormal (|RRᵀ − I| entry by entry) a model
/// may have: rotations the trainer writes are orthonormal to ~1e-15.
pub const ROTATION_TOLERANCE: f64 = 1e-9;

//! The discrete flow in the trainer: primal (shared with the runtime) and tangent.

//! The fields in their kernels' own expansions (format 5, docs/DESIGN.md §11): the basis
//! functions (`basis`) and the fields' sums over them with a stage's weights (`fields`).

pub mod basis;
pub mod fields;

pub use basis::{for_each_task_basis, joint_row_len, write_joint_basis};

//! The fields in their kernels' own expansions (format 5, docs/DESIGN.md §11): the basis
//! functions (`basis_functions`) and the fields' sums over them with a stage's weights (`fields`).

pub mod basis_functions;
pub mod fields;

pub use basis_functions::{
    for_each_task_basis, for_each_task_basis_with_orders, joint_orders, joint_row_len, task_orders, write_joint_basis,
    write_joint_basis_with_orders,
};

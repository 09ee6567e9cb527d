//! Evaluation harnesses: every method on the same data ([`compare`]), and where a simulated arm's
//! tool goes when each method turns a target into a joint command ([`commanded`], [`commanded_pose`];
//! a blob's commands for many targets: [`compensation`]). The methods enter as fitted corrections
//! ([`correction`]) and as a list of [`peers`] the CLI chooses; no harness names a peer. Whether a
//! blob still holds on fresh poses: [`check`].

pub mod blob_match;
pub mod check;
pub mod command_check;
pub mod commanded;
pub mod commanded_pose;
pub mod compare;
pub mod compensation;
pub mod correction;
pub mod peers;
pub mod pose_errors;

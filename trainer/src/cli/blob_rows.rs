//! A blob read for a command: decoded here against the command's model flag (what `cbd eval`,
//! `cbd check`, `cbd compensate` and `cbd plan --check` share); the face evaluates it.

use crate::cli::ModelArgs;
use crate::error::Result;
use std::path::Path;

/// `blob` (read from `path`) decoded and checked to fit `nominal` and `spec` ([`crate::face::decode_blob`]),
/// a misfit naming the `--model` file.
pub(crate) fn decode_fitting<'b>(
    blob: &'b [u8],
    path: &Path,
    model: &ModelArgs,
    nominal: &cbd_protocol::NominalModel,
    spec: &crate::data::column_spec::ColumnSpec,
) -> Result<cbd_protocol::Model<'b>> {
    crate::face::decode_blob(blob, path, model.model.as_deref(), nominal, spec)
}

//! A blob read for a command: decoded here against the command's model flag (what `cbd eval`,
//! `cbd check`, `cbd compensate` and `cbd plan --check` share); the face evaluates it.

use crate::cli::args::blob_misfit;
use crate::cli::ModelArgs;
use crate::error::{Context, Result};
use std::path::Path;

/// `blob` (read from `path`) decoded and checked to fit `nominal`, the model file's chain (joints
/// and their kinds, task coordinates, tool points, length unit), and its import `spec` (the frame
/// rows are read into, where the blob records it); a misfit names both files.
pub(crate) fn decode_fitting<'b>(
    blob: &'b [u8],
    path: &Path,
    model: &ModelArgs,
    nominal: &cbd_protocol::NominalModel,
    spec: &crate::data::column_spec::ColumnSpec,
) -> Result<cbd_protocol::Model<'b>> {
    let decoded = cbd_protocol::decode(blob).context(path.display())?;
    crate::evaluation::blob_match::check_blob_fits_model_file(&decoded, nominal, spec).map_err(|why| blob_misfit(path, model, why))?;
    Ok(decoded)
}

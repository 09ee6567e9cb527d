//! Measurement data: joint configurations and measured positions.

/// N measured pairs (x_i, y_i): joint configurations (`n` per row) and positions (`m` per row),
/// in the nominal model's units (radians / length unit of the model). A file of targets alone
/// (`cbd compensate --targets`) has n = 0, one of seeds alone m = 0.
///
/// With several tool points per pose (docs/DESIGN.md §12) a row is one (pose, tool point): pose-major,
/// row r = pose · `points_per_pose` + j holds tool point j, the pose's configuration repeated. Folds
/// and subsets of whole poses ([`Measurements::fold`], [`Measurements::pose_rows`]) keep a pose's
/// points together, so the nominal model's point of row r is always r mod `points_per_pose`.
#[derive(Debug, Clone, PartialEq)]
pub struct Measurements {
    pub n_joints: usize,
    pub task_dim: usize,
    /// Tool points measured per pose (1: one point, today's data).
    pub points_per_pose: usize,
    /// N × n, row-major.
    pub joints: Vec<f64>,
    /// N × m, row-major.
    pub positions: Vec<f64>,
}

impl Measurements {
    pub fn new(n_joints: usize, task_dim: usize) -> Self {
        Measurements { n_joints, task_dim, points_per_pose: 1, joints: Vec::new(), positions: Vec::new() }
    }
    /// Empty, for `points_per_pose` tool points per pose.
    pub fn with_points(n_joints: usize, task_dim: usize, points_per_pose: usize) -> Self {
        Measurements { points_per_pose: points_per_pose.max(1), ..Measurements::new(n_joints, task_dim) }
    }
    /// Number of poses (rows / points per pose).
    pub fn pose_count(&self) -> usize {
        self.len() / self.points_per_pose.max(1)
    }
    /// The row indices of the poses at `poses` (every point of each, in order).
    pub fn pose_rows(&self, poses: &[usize]) -> Vec<usize> {
        let p = self.points_per_pose.max(1);
        poses.iter().flat_map(|&k| k * p..(k + 1) * p).collect()
    }
    /// The rows of at most `limit` rows' worth of evenly spaced whole poses
    /// ([`evenly_spaced_rows`] over the poses; the rows themselves with one point per pose).
    pub fn evenly_spaced_pose_rows(&self, limit: usize) -> Vec<usize> {
        let p = self.points_per_pose.max(1);
        self.pose_rows(&evenly_spaced_rows(self.pose_count(), (limit / p).max(1)))
    }
    /// The rows of tool point `j` (one per pose), as one-point data.
    pub fn point(&self, j: usize) -> Measurements {
        let p = self.points_per_pose.max(1);
        let rows: Vec<usize> = (0..self.pose_count()).map(|k| k * p + j).collect();
        Measurements { points_per_pose: 1, ..self.subset(&rows) }
    }
    pub fn len(&self) -> usize {
        if self.n_joints > 0 {
            self.joints.len() / self.n_joints
        } else {
            self.positions.len() / self.task_dim.max(1)
        }
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    pub fn push(&mut self, joints: &[f64], position: &[f64]) {
        self.joints.extend_from_slice(joints);
        self.positions.extend_from_slice(position);
    }
    pub fn joints(&self, i: usize) -> &[f64] {
        &self.joints[i * self.n_joints..(i + 1) * self.n_joints]
    }
    pub fn position(&self, i: usize) -> &[f64] {
        &self.positions[i * self.task_dim..(i + 1) * self.task_dim]
    }
    /// Fold `fold` of `folds` interleaved folds (pose k is held out when k mod folds = fold; a
    /// pose's points stay together): (the other rows, the held-out rows).
    pub fn fold(&self, folds: usize, fold: usize) -> (Measurements, Measurements) {
        let p = self.points_per_pose.max(1);
        let (rest, held): (Vec<usize>, Vec<usize>) = (0..self.len()).partition(|i| (i / p) % folds != fold);
        (self.subset(&rest), self.subset(&held))
    }
    /// The rows at `indices`, in that order (with several points per pose: whole poses, e.g.
    /// [`Measurements::pose_rows`], or the result's points no longer match its rows).
    pub fn subset(&self, indices: &[usize]) -> Measurements {
        let mut out = Measurements::with_points(self.n_joints, self.task_dim, self.points_per_pose);
        for &i in indices {
            out.push(self.joints(i), self.position(i));
        }
        out
    }
}

/// Largest blob read: a blob of the largest model the trainer fits (N = 4096 points, 6 joints,
/// 3-D task) is under 1 MiB; 64 MiB leaves room and stops `--blob /dev/zero` at once.
pub const MAX_BLOB_BYTES: u64 = 64 << 20;

/// Largest model file (TOML) read.
pub const MAX_MODEL_FILE_BYTES: u64 = 1 << 20;

/// Largest URDF read: real arm descriptions are tens of kilobytes (meshes are separate files);
/// the parser holds about 60 times the file in memory (a 34 MB URDF took 2.2 GB).
pub const MAX_URDF_BYTES: u64 = 8 << 20;

/// Reads at most `cap` bytes of `path`; a longer file (or an endless one such as `/dev/zero`) is an
/// error naming the path, what it is and the cap, before the memory runs out.
pub fn read_capped(path: &std::path::Path, cap: u64, what: &str) -> crate::Result<Vec<u8>> {
    use std::io::Read;
    let file = std::fs::File::open(path).map_err(|e| crate::Error::io(path, e))?;
    crate::io::note_input(&format!("the {what}"), path);
    let mut bytes = Vec::new();
    file.take(cap + 1).read_to_end(&mut bytes).map_err(|e| crate::Error::io(path, e))?;
    if bytes.len() as u64 > cap {
        let reason = format!("larger than {} MiB, the most a {what} may be", cap >> 20);
        return Err(crate::Error::Path { path: path.to_path_buf(), reason });
    }
    Ok(bytes)
}

pub mod column_spec;
pub mod csv_import;
pub mod effects_section;
mod evenly_spaced;
pub use evenly_spaced::evenly_spaced_rows;
pub mod import_error;
pub mod joint_columns;
pub mod joint_map;
pub mod model_file;
pub mod nominal_check;
pub mod units;

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 17 item 8: `--blob /dev/zero` read until the memory ran out.
    #[test]
    fn blob_and_urdf_reads_are_capped() {
        let e = read_capped(std::path::Path::new("/dev/zero"), MAX_BLOB_BYTES, "blob").unwrap_err().to_string();
        assert!(e.starts_with("/dev/zero: larger than 64 MiB, the most a blob may be"), "{e}");
        let dir = std::env::temp_dir().join(format!("cbd-read-capped-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("a.bin");
        std::fs::write(&f, vec![7u8; 1025]).unwrap();
        assert_eq!(read_capped(&f, 1025, "blob").unwrap().len(), 1025);
        assert!(read_capped(&f, 1024, "URDF").unwrap_err().to_string().contains("the most a URDF may be"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

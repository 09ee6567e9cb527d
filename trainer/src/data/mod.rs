//! Measurement data: joint configurations and measured positions.

/// N measured pairs (x_i, y_i): joint configurations (`n` per row) and positions (`m` per row),
/// in the nominal model's units (radians / length unit of the model). A file of targets alone
/// (`cbd compensate --targets`) has n = 0, one of seeds alone m = 0.
#[derive(Debug, Clone, PartialEq)]
pub struct Measurements {
    pub n_joints: usize,
    pub task_dim: usize,
    /// N × n, row-major.
    pub joints: Vec<f64>,
    /// N × m, row-major.
    pub positions: Vec<f64>,
}

impl Measurements {
    pub fn new(n_joints: usize, task_dim: usize) -> Self {
        Measurements { n_joints, task_dim, joints: Vec::new(), positions: Vec::new() }
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
    /// Fold `fold` of `folds` interleaved folds (row i is held out when i mod folds = fold):
    /// (the other rows, the held-out rows).
    pub fn fold(&self, folds: usize, fold: usize) -> (Measurements, Measurements) {
        let (rest, held): (Vec<usize>, Vec<usize>) = (0..self.len()).partition(|i| i % folds != fold);
        (self.subset(&rest), self.subset(&held))
    }
    /// The rows at `indices`, in that order.
    pub fn subset(&self, indices: &[usize]) -> Measurements {
        let mut out = Measurements::new(self.n_joints, self.task_dim);
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

pub mod csv_import;
pub mod effects_section;
mod evenly_spaced;
pub use evenly_spaced::evenly_spaced_rows;
pub mod import_error;
pub mod joint_map;
pub mod limits;
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

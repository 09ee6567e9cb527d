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
    /// Whether the rows are a time sequence ([`RowOrder`]): what held-out rows may be.
    pub order: RowOrder,
}

/// Whether the rows are in the order they were measured (docs/DESIGN.md §3 "Folds that respect
/// measurement order", issue 49 item 1). Part of a real arm's residual belongs to the moment of
/// measurement (drift: on the UR5 rows lag-1 correlation 0.47 after the DH fit), so a held-out row
/// between two training rows measured just before and after it flatters every model. Measured rows
/// are held out in contiguous blocks of poses, and the training rows within [`ORDER_GAP_POSES`] of a
/// block are left out; unordered rows (a grid, a shuffled campaign) are held out interleaved.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RowOrder {
    /// The file's rows are in measurement order (the default: a measurement campaign).
    #[default]
    Measured,
    /// The rows carry no time order (a grid, simulated independent poses, a shuffled file).
    Unordered,
}

impl RowOrder {
    /// The model file's spelling.
    pub fn name(self) -> &'static str {
        match self {
            RowOrder::Measured => "measured",
            RowOrder::Unordered => "unordered",
        }
    }
}

/// Poses left out of training on each side of a held-out block of measured rows: the UR5 residual's
/// correlation in row order is 0.20 at lag 5 and ≈ 0 by lag 50, its drift's length 8.4 poses
/// (docs/DESIGN.md §3); at most a quarter of the block, so that small sets keep their training rows.
pub const ORDER_GAP_POSES: usize = 10;

/// Pose ranges of fold `fold` of `folds` over `poses` measured poses: (the held-out block, the
/// block widened by the gap on each side — the poses not used for training).
pub fn blocked_fold(poses: usize, folds: usize, fold: usize) -> (std::ops::Range<usize>, std::ops::Range<usize>) {
    let folds = folds.max(1);
    let held = fold * poses / folds..((fold + 1) * poses / folds).min(poses);
    (held.clone(), with_gap(held, poses))
}

/// The held-out block `held` of `poses` measured poses widened by the gap on each side
/// ([`ORDER_GAP_POSES`], at most a quarter of the block): the poses not used for training.
pub fn with_gap(held: std::ops::Range<usize>, poses: usize) -> std::ops::Range<usize> {
    let gap = ORDER_GAP_POSES.min(held.len() / 4);
    held.start.saturating_sub(gap)..(held.end + gap).min(poses)
}

/// The indices of at most `limit` of `count` rows, evenly spaced through them (all of them when
/// `count ≤ limit`).
pub fn evenly_spaced_rows(count: usize, limit: usize) -> Vec<usize> {
    if count > limit {
        (0..limit).map(|i| i * count / limit).collect()
    } else {
        (0..count).collect()
    }
}

impl Measurements {
    pub fn new(n_joints: usize, task_dim: usize) -> Self {
        Measurements { n_joints, task_dim, points_per_pose: 1, joints: Vec::new(), positions: Vec::new(), order: RowOrder::Measured }
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
    /// Fold `fold` of `folds` (a pose's points stay together): (the training rows, the held-out
    /// rows). Measured rows ([`RowOrder`]): the fold-th contiguous block of poses is held out and the
    /// poses within the gap of it are in neither ([`blocked_fold`]); unordered rows: pose k is held
    /// out when k mod folds = fold.
    pub fn fold(&self, folds: usize, fold: usize) -> (Measurements, Measurements) {
        let p = self.points_per_pose.max(1);
        let (rest, held): (Vec<usize>, Vec<usize>) = match self.order {
            RowOrder::Unordered => (0..self.len()).partition(|i| (i / p) % folds.max(1) != fold),
            RowOrder::Measured => {
                let (held, left_out) = blocked_fold(self.pose_count(), folds, fold);
                let rest = (0..self.len()).filter(|i| !left_out.contains(&(i / p))).collect();
                (rest, (0..self.len()).filter(|i| held.contains(&(i / p))).collect())
            }
        };
        (self.subset(&rest), self.subset(&held))
    }
    /// What `model` leaves of the measured positions (measured − predicted, m per row, row-major).
    pub fn residual_of(&self, model: &cbd_protocol::NominalModel) -> Vec<f64> {
        crate::nominal::positions(model, &self.joints, self.task_dim).iter().zip(&self.positions).map(|(k, y)| y - k).collect()
    }
    /// Task-space normalisation of the positions: offset = their mean, scale = RMS distance to it.
    pub fn normalisation(&self) -> cbd_protocol::Normalisation {
        let m = self.task_dim;
        let count = self.len().max(1) as f64;
        let mut offset = [0.0; 3];
        for y in self.positions.chunks_exact(m) {
            for c in 0..m {
                offset[c] += y[c] / count;
            }
        }
        let r2: f64 = self.positions.chunks_exact(m).map(|y| (0..m).map(|c| (y[c] - offset[c]).powi(2)).sum::<f64>()).sum::<f64>() / count;
        let scale = if r2 > 0.0 && r2.is_finite() { r2.sqrt() } else { 1.0 };
        cbd_protocol::Normalisation { task_offset: offset, task_scale: scale }
    }
    /// The diagonal of the positions' bounding box: the rows' extent (0 for one row).
    pub fn bounding_box_diagonal(&self) -> f64 {
        let m = self.task_dim;
        let mut lo = vec![f64::INFINITY; m];
        let mut hi = vec![f64::NEG_INFINITY; m];
        for i in 0..self.len() {
            for (c, y) in self.position(i).iter().enumerate() {
                lo[c] = lo[c].min(*y);
                hi[c] = hi[c].max(*y);
            }
        }
        lo.iter().zip(&hi).map(|(l, h)| (h - l) * (h - l)).sum::<f64>().sqrt()
    }
    /// The rows at `indices`, in that order (with several points per pose: whole poses, e.g.
    /// [`Measurements::pose_rows`], or the result's points no longer match its rows).
    pub fn subset(&self, indices: &[usize]) -> Measurements {
        let mut out = Measurements { order: self.order, ..Measurements::with_points(self.n_joints, self.task_dim, self.points_per_pose) };
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
pub mod import_error;
pub mod import_frame;
pub mod joint_columns;
pub mod joint_map;
pub mod model_file;
pub mod preparation;
pub mod stage_rows;
pub mod units;

#[cfg(test)]
mod tests {
    use super::*;

    fn rows(poses: usize, points: usize, order: RowOrder) -> Measurements {
        let mut d = Measurements { order, ..Measurements::with_points(1, 1, points) };
        for k in 0..poses {
            for j in 0..points {
                d.push(&[k as f64], &[j as f64]);
            }
        }
        d
    }

    #[test]
    fn measured_rows_are_held_out_in_blocks_with_a_gap_and_unordered_rows_interleaved() {
        let d = rows(100, 2, RowOrder::Measured);
        let poses = |m: &Measurements| -> Vec<usize> { m.joints.iter().step_by(2).map(|q| *q as usize).collect() };
        let mut every_held = Vec::new();
        for fold in 0..5 {
            let (train, held) = d.fold(5, fold);
            let (h, t) = (poses(&held), poses(&train));
            assert_eq!(h, (20 * fold..20 * fold + 20).collect::<Vec<_>>());
            // The gap: 5 poses (a quarter of the block) on each side of it are in neither set.
            let expected: Vec<usize> = (0..100).filter(|k| *k + 5 < 20 * fold || *k >= 20 * fold + 25).collect();
            assert_eq!(t, expected, "fold {fold}");
            assert_eq!(train.order, RowOrder::Measured);
            assert!(held.positions.chunks(2).all(|p| p == [0.0, 1.0]), "a pose's points stay together");
            every_held.extend(h);
        }
        assert_eq!(every_held, (0..100).collect::<Vec<_>>(), "every pose is held out once");
        // Large blocks: the gap is ORDER_GAP_POSES.
        let (held, out) = blocked_fold(1000, 5, 2);
        assert_eq!((held, out), (400..600, 390..610));
        let u = rows(10, 1, RowOrder::Unordered);
        let (train, held) = u.fold(5, 1);
        assert_eq!(held.joints, vec![1.0, 6.0]);
        assert_eq!(train.len(), 8);
    }

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

    #[test]
    fn rows_are_spread_from_the_first_and_all_kept_under_the_limit() {
        assert_eq!(evenly_spaced_rows(10, 4), vec![0, 2, 5, 7]);
        assert_eq!(evenly_spaced_rows(3, 4), vec![0, 1, 2]);
        assert_eq!(evenly_spaced_rows(5, 0), Vec::<usize>::new());
    }
}

//! Measurement import from CSV: named joint and position columns, unit conversion, and errors
//! that name the file, the line and the column.

use super::model_file::{AngleUnit, ImportError, LengthUnit};
use super::Measurements;
use cbd_protocol::JointKind;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// Which columns hold what, and in which units.
#[derive(Debug, Clone, PartialEq)]
pub struct ColumnSpec {
    /// One column per joint, in chain order.
    pub joint_columns: Vec<String>,
    /// One column per task coordinate.
    pub position_columns: Vec<String>,
    /// Kind of each joint: revolute columns are in `angle_unit`, prismatic ones in `length_unit`.
    pub joint_kinds: Vec<JointKind>,
    /// Unit of the revolute joint columns in the file (converted to radians).
    pub angle_unit: AngleUnit,
    /// Unit of the position (and prismatic joint) columns in the file.
    pub length_unit: LengthUnit,
    /// The model's length unit, which lengths are converted to.
    pub model_length_unit: LengthUnit,
    /// Fewer data rows is an error.
    pub min_rows: usize,
}

/// A row whose joint configuration repeats an earlier row's exactly.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Duplicate {
    pub line: u64,
    pub first_line: u64,
}

/// The imported data plus what the import noticed.
#[derive(Debug, Clone, PartialEq)]
pub struct ImportedMeasurements {
    pub measurements: Measurements,
    /// File line (1-based, header = 1) of each data row.
    pub lines: Vec<u64>,
    /// Repeated configurations (kept in the data; the warnings say so).
    pub duplicates: Vec<Duplicate>,
}

impl ImportedMeasurements {
    /// Human-readable warnings (duplicate configurations), one per entry.
    pub fn warnings(&self, file: &Path) -> Vec<String> {
        self.duplicates
            .iter()
            .map(|d| format!("{}:{}: joint configuration repeats line {}", file.display(), d.line, d.first_line))
            .collect()
    }
}

/// Reads measurements from a CSV file with a header row.
pub fn read_measurements(path: impl AsRef<Path>, spec: &ColumnSpec) -> Result<ImportedMeasurements, ImportError> {
    let path = path.as_ref();
    let file = std::fs::File::open(path).map_err(|e| ImportError::Io { file: path.to_path_buf(), message: e.to_string() })?;
    read_measurements_from(file, path, spec)
}

/// As [`read_measurements`], from any reader; `path` names the source in errors.
pub fn read_measurements_from(reader: impl std::io::Read, path: &Path, spec: &ColumnSpec) -> Result<ImportedMeasurements, ImportError> {
    let file: PathBuf = path.to_path_buf();
    let err = |line: Option<u64>, column: Option<&str>, message: String| ImportError::Csv {
        file: file.clone(),
        line,
        column: column.map(str::to_string),
        message,
    };
    if spec.joint_columns.len() != spec.joint_kinds.len() {
        return Err(err(
            None,
            None,
            format!("{} joint columns named for a model with {} joints", spec.joint_columns.len(), spec.joint_kinds.len()),
        ));
    }
    let mut rdr = csv::ReaderBuilder::new().has_headers(true).flexible(true).trim(csv::Trim::All).from_reader(reader);
    let header = rdr.headers().map_err(|e| err(Some(1), None, format!("cannot read the header: {e}")))?.clone();
    if header.is_empty() || (header.len() == 1 && header[0].is_empty()) {
        return Err(err(Some(1), None, "empty file: no header row".into()));
    }
    let find = |name: &str| -> Result<usize, ImportError> {
        let hits: Vec<usize> = header.iter().enumerate().filter(|(_, h)| *h == name).map(|(i, _)| i).collect();
        match hits.as_slice() {
            [i] => Ok(*i),
            [] => Err(err(
                Some(1),
                Some(name),
                format!("no such column in the header (columns: {})", header.iter().collect::<Vec<_>>().join(", ")),
            )),
            _ => Err(err(Some(1), Some(name), "column name appears more than once in the header".into())),
        }
    };
    let joint_idx = spec.joint_columns.iter().map(|c| find(c)).collect::<Result<Vec<_>, _>>()?;
    let pos_idx = spec.position_columns.iter().map(|c| find(c)).collect::<Result<Vec<_>, _>>()?;
    let rad = spec.angle_unit.radians();
    let len = spec.length_unit.factor_to(spec.model_length_unit);
    let joint_factor: Vec<f64> = spec.joint_kinds.iter().map(|k| if *k == JointKind::Revolute { rad } else { len }).collect();

    let (n, m) = (spec.joint_columns.len(), spec.position_columns.len());
    let mut data = Measurements::new(n, m);
    let mut lines = Vec::new();
    let mut seen: HashMap<Vec<u64>, u64> = HashMap::new();
    let mut duplicates = Vec::new();
    let mut record = csv::StringRecord::new();
    let (mut q, mut y) = (vec![0.0; n], vec![0.0; m]);
    loop {
        let more = rdr.read_record(&mut record).map_err(|e| {
            let line = e.position().map(|p| p.line());
            err(line, None, format!("malformed CSV: {e}"))
        })?;
        if !more {
            break;
        }
        let line = record.position().map(|p| p.line()).unwrap_or(0);
        if record.len() == 1 && record[0].is_empty() {
            continue; // blank line
        }
        if record.len() != header.len() {
            return Err(err(Some(line), None, format!("{} fields; the header has {}", record.len(), header.len())));
        }
        let value = |idx: usize, name: &str| -> Result<f64, ImportError> {
            let text = &record[idx];
            if text.is_empty() {
                return Err(err(Some(line), Some(name), "missing value".into()));
            }
            let v: f64 = text.parse().map_err(|_| err(Some(line), Some(name), format!("not a number: '{text}'")))?;
            if !v.is_finite() {
                return Err(err(Some(line), Some(name), format!("not a finite number: '{text}'")));
            }
            Ok(v)
        };
        for d in 0..n {
            q[d] = value(joint_idx[d], &spec.joint_columns[d])? * joint_factor[d];
        }
        for c in 0..m {
            y[c] = value(pos_idx[c], &spec.position_columns[c])? * len;
        }
        let key: Vec<u64> = q.iter().map(|v| (v + 0.0).to_bits()).collect();
        if let Some(&first_line) = seen.get(&key) {
            duplicates.push(Duplicate { line, first_line });
        } else {
            seen.insert(key, line);
        }
        data.push(&q, &y);
        lines.push(line);
    }
    if data.len() < spec.min_rows.max(1) {
        return Err(err(None, None, format!("{} data rows; at least {} needed", data.len(), spec.min_rows.max(1))));
    }
    Ok(ImportedMeasurements { measurements: data, lines, duplicates })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec() -> ColumnSpec {
        ColumnSpec {
            joint_columns: vec!["q1".into(), "s2".into()],
            position_columns: vec!["x".into(), "y".into(), "z".into()],
            joint_kinds: vec![JointKind::Revolute, JointKind::Prismatic],
            angle_unit: AngleUnit::Deg,
            length_unit: LengthUnit::Mm,
            model_length_unit: LengthUnit::M,
            min_rows: 2,
        }
    }

    fn read(text: &str) -> Result<ImportedMeasurements, ImportError> {
        read_measurements_from(text.as_bytes(), Path::new("meas.csv"), &spec())
    }

    fn csv_err(text: &str) -> (Option<u64>, Option<String>, String) {
        match read(text).unwrap_err() {
            ImportError::Csv { line, column, message, .. } => (line, column, message),
            e => panic!("{e}"),
        }
    }

    #[test]
    fn converts_units_and_keeps_column_order() {
        let r = read("z,extra,x,y,s2,q1\n3,a,1,2,500,180\n30,b,10,20,-250,-90\n").unwrap();
        let d = &r.measurements;
        assert_eq!((d.len(), d.n_joints, d.task_dim), (2, 2, 3));
        assert!((d.joints(0)[0] - std::f64::consts::PI).abs() < 1e-15);
        assert_eq!(d.joints(0)[1], 0.5);
        assert_eq!(d.position(0), &[0.001, 0.002, 0.003]);
        assert_eq!(d.joints(1)[1], -0.25);
        assert_eq!(r.lines, vec![2, 3]);
        assert!(r.duplicates.is_empty());
    }

    #[test]
    fn missing_column_names_it() {
        let (line, col, msg) = csv_err("q1,s2,x,y\n1,2,3,4\n");
        assert_eq!((line, col.as_deref()), (Some(1), Some("z")));
        assert!(msg.contains("no such column"));
        let e = read("q1,s2,x,y\n1,2,3,4\n").unwrap_err().to_string();
        assert!(e.starts_with("meas.csv:1: column 'z'"), "{e}");
    }

    #[test]
    fn missing_value_names_line_and_column() {
        let (line, col, msg) = csv_err("q1,s2,x,y,z\n1,2,3,4,5\n1,2,,4,5\n");
        assert_eq!((line, col.as_deref(), msg.as_str()), (Some(3), Some("x"), "missing value"));
    }

    #[test]
    fn non_numeric_value_names_line_and_column() {
        let (line, col, msg) = csv_err("q1,s2,x,y,z\n1,2,3,4,5\n1,2,3,4,5\n1,two,3,4,5\n");
        assert_eq!((line, col.as_deref()), (Some(4), Some("s2")));
        assert!(msg.contains("'two'"));
    }

    #[test]
    fn non_finite_value_names_line_and_column() {
        for bad in ["NaN", "inf", "-infinity"] {
            let (line, col, msg) = csv_err(&format!("q1,s2,x,y,z\n1,2,3,4,5\n1,2,3,4,{bad}\n"));
            assert_eq!((line, col.as_deref()), (Some(3), Some("z")));
            assert!(msg.contains("finite"), "{msg}");
        }
    }

    #[test]
    fn wrong_field_count_names_the_line() {
        let (line, col, msg) = csv_err("q1,s2,x,y,z\n1,2,3,4,5\n1,2,3,4\n");
        assert_eq!((line, col), (Some(3), None));
        assert!(msg.contains("4 fields; the header has 5"), "{msg}");
        let (line, _, _) = csv_err("q1,s2,x,y,z\n1,2,3,4,5\n1,2,3,4,5,6\n");
        assert_eq!(line, Some(3));
    }

    #[test]
    fn too_few_rows() {
        let (_, _, msg) = csv_err("q1,s2,x,y,z\n1,2,3,4,5\n");
        assert!(msg.contains("1 data rows; at least 2"), "{msg}");
        let (_, _, msg) = csv_err("q1,s2,x,y,z\n");
        assert!(msg.contains("0 data rows"), "{msg}");
        let e = read("").unwrap_err().to_string();
        assert!(e.contains("meas.csv"), "{e}");
    }

    #[test]
    fn duplicate_configurations_are_reported() {
        let r = read("q1,s2,x,y,z\n1,2,3,4,5\n7,8,9,9,9\n1,2,3.1,4,5\n").unwrap();
        assert_eq!(r.measurements.len(), 3);
        assert_eq!(r.duplicates, vec![Duplicate { line: 4, first_line: 2 }]);
        let w = r.warnings(Path::new("meas.csv"));
        assert_eq!(w, vec!["meas.csv:4: joint configuration repeats line 2".to_string()]);
    }

    #[test]
    fn missing_file_is_an_io_error_naming_it() {
        let e = read_measurements("/nonexistent/dir/m.csv", &spec()).unwrap_err();
        assert!(matches!(e, ImportError::Io { .. }) && e.to_string().contains("/nonexistent/dir/m.csv"));
    }
}

//! Measurement import from CSV: named joint and position columns, unit conversion, and errors
//! that name the file, the line and the column.

pub use super::column_spec::{default_joint_limits, ColumnSpec, OrientationColumns, RANGE_FROM_MODEL_FILE};
use super::import_error::ImportError;
use super::Measurements;
use crate::limits::MAX_MAGNITUDE;
use cbd_protocol::JointKind;
use std::collections::HashMap;
use std::path::Path;

/// Largest departure of a measured quaternion's norm from 1, or of a rotation matrix's rows from
/// orthonormal, before it is refused as not a rotation (a few printed digits stay well inside).
pub const ROTATION_TOLERANCE: f64 = 1e-3;

/// A row whose joint configuration repeats an earlier row's exactly, with positions that agree
/// within the repeat tolerance (kept in the data: a repeated measurement).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Duplicate {
    pub line: u64,
    pub first_line: u64,
    /// Distance between the two measured positions, model length unit.
    pub distance: f64,
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
    /// Human-readable warnings (duplicate configurations): one per entry for the first
    /// [`DUPLICATES_LISTED`], then one line counting the rest (a file of 100 000 repeated rows
    /// gave 99 999 lines).
    pub fn warnings(&self, file: &Path) -> Vec<String> {
        let mut out: Vec<String> = self
            .duplicates
            .iter()
            .take(DUPLICATES_LISTED)
            .map(|d| {
                format!(
                    "{}:{}: joint configuration repeats line {} (positions {:.3e} apart)",
                    file.display(),
                    d.line,
                    d.first_line,
                    d.distance
                )
            })
            .collect();
        let rest = self.duplicates.len().saturating_sub(DUPLICATES_LISTED);
        if rest > 0 {
            let farthest = self.duplicates.iter().map(|d| d.distance).fold(0.0, f64::max);
            out.push(format!(
                "{}: {rest} more rows repeat an earlier joint configuration ({} in all, positions at most {farthest:.3e} apart); all are kept",
                file.display(),
                self.duplicates.len()
            ));
        }
        out
    }
}

/// Repeated configurations warned about one by one; the rest are counted on one line.
pub const DUPLICATES_LISTED: usize = 5;

/// Reads measurements from a CSV file with a header row.
pub fn read_measurements(path: impl AsRef<Path>, spec: &ColumnSpec) -> Result<ImportedMeasurements, ImportError> {
    let path = path.as_ref();
    let file = std::fs::File::open(path).map_err(|e| ImportError::Io { file: path.to_path_buf(), message: e.to_string() })?;
    crate::io::note_input("a measurement file", path);
    read_measurements_from(file, path, spec)
}

/// As [`read_measurements`], from any reader; `path` names the source in errors.
pub fn read_measurements_from(reader: impl std::io::Read, path: &Path, spec: &ColumnSpec) -> Result<ImportedMeasurements, ImportError> {
    use std::io::Read;
    let err = Errors { source: Source::File(path) };
    check_spec(spec, err)?;
    let mut bytes = Vec::new();
    reader
        .take(MAX_CSV_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| ImportError::Io { file: path.to_path_buf(), message: e.to_string() })?;
    if bytes.len() as u64 > MAX_CSV_BYTES {
        return Err(err.at(None, None, format!("larger than {} MiB, the most a measurement file may be", MAX_CSV_BYTES >> 20)));
    }
    check_text(&bytes, err)?;
    // Records come in file order, so one cursor counts each byte's newline once: linear in the file.
    let lines_seen = std::cell::RefCell::new(LineCounter::new(&bytes));
    let line_of = |pos: &csv::Position| lines_seen.borrow_mut().line_at(pos.byte());
    let mut rdr = csv::ReaderBuilder::new().has_headers(true).flexible(true).trim(csv::Trim::All).from_reader(bytes.as_slice());
    let header = rdr.headers().map_err(|e| err.at(Some(1), None, format!("cannot read the header: {e}")))?.clone();
    if header.is_empty() || (header.len() == 1 && header[0].is_empty()) {
        return Err(err.at(Some(1), None, "empty file: no header row".into()));
    }
    let row = RowReader::new(&header, spec, err)?;
    let mut rows = Assembler::new(row);
    let mut record = csv::StringRecord::new();
    loop {
        let more = rdr.read_record(&mut record).map_err(|e| {
            let line = e.position().map(line_of);
            err.at(line, None, format!("malformed CSV: {e}"))
        })?;
        if !more {
            break;
        }
        let line = record.position().map(line_of).unwrap_or(0);
        if record.len() == 1 && record[0].is_empty() {
            continue; // blank line
        }
        if record.len() != header.len() {
            return Err(err.at(Some(line), None, format!("{} fields; the header has {}", record.len(), header.len())));
        }
        rows.add(&record, line)?;
    }
    rows.finish()
}

/// Measurements from rows of numbers, as [`read_measurements_from`] reads a CSV file's: `q` holds
/// `rows` rows of the spec's joint columns and `y` as many rows of its position columns (then a
/// pose's orientation columns), row-major, each number in its column's unit — the numbers a CSV
/// file for the same model file holds. The same conversion and checks apply, row by row, by the
/// same code; errors name `source` and the 0-based row (`(q, y) row 3: column 'q2_deg': …`), and
/// row r is line r + 2 in [`ImportedMeasurements::lines`] (as though a header were line 1).
pub fn measurements_from_rows(
    source: &str,
    q: &[f64],
    y: &[f64],
    rows: usize,
    spec: &ColumnSpec,
) -> Result<ImportedMeasurements, ImportError> {
    let err = Errors { source: Source::Rows(source) };
    check_spec(spec, err)?;
    let (n, m) = (spec.joint_columns.len(), y_width(spec));
    if q.len() != rows * n || y.len() != rows * m {
        return Err(err.at(
            None,
            None,
            format!(
                "{rows} rows of {n} joint and {m} other columns need {} and {} values; given {} and {}",
                rows * n,
                rows * m,
                q.len(),
                y.len()
            ),
        ));
    }
    let mut assembler = Assembler::new(RowReader::in_order(spec, err));
    for r in 0..rows {
        let values = Numbers { q: &q[r * n..(r + 1) * n], y: &y[r * m..(r + 1) * m] };
        assembler.add(&values, r as u64 + 2)?;
    }
    assembler.finish()
}

/// Columns after the joints in a row of numbers: the positions, then a pose's orientation.
fn y_width(spec: &ColumnSpec) -> usize {
    spec.position_columns.len() + spec.orientation_columns.as_ref().map_or(0, |o| o.names().len())
}

/// The spec's joint columns agree with its model's joints.
fn check_spec(spec: &ColumnSpec, err: Errors<'_>) -> Result<(), ImportError> {
    if spec.joint_columns.len() != spec.joint_kinds.len() || spec.joint_limits.len() != spec.joint_kinds.len() {
        return Err(err.at(
            None,
            None,
            format!("{} joint columns named for a model with {} joints", spec.joint_columns.len(), spec.joint_kinds.len()),
        ));
    }
    Ok(())
}

/// One row's values: a CSV record's fields (text) or numbers.
trait Row {
    fn field(&self, idx: usize) -> Field<'_>;
}

enum Field<'r> {
    Text(&'r str),
    Number(f64),
}

impl Field<'_> {
    /// The value as given, for a message: an excerpt of the text, a number in shortest form.
    fn quoted(&self) -> String {
        match self {
            Field::Text(t) => crate::error::excerpt(t),
            Field::Number(v) => format!("{v:?}"),
        }
    }
}

impl Row for csv::StringRecord {
    fn field(&self, idx: usize) -> Field<'_> {
        Field::Text(&self[idx])
    }
}

/// A row of numbers: the joint columns, then the others.
struct Numbers<'r> {
    q: &'r [f64],
    y: &'r [f64],
}

impl Row for Numbers<'_> {
    fn field(&self, idx: usize) -> Field<'_> {
        Field::Number(if idx < self.q.len() { self.q[idx] } else { self.y[idx - self.q.len()] })
    }
}

/// The rows read so far, converted and checked, as measurements: what every source of rows
/// (a CSV file, arrays) shares.
struct Assembler<'a> {
    row: RowReader<'a>,
    data: Measurements,
    /// Task coordinates per data row and tool points per pose.
    m: usize,
    points: usize,
    point_values: Vec<f64>,
    lines: Vec<u64>,
    /// Joint configuration bits → row index of its first occurrence.
    seen: HashMap<Vec<u64>, usize>,
    repeats: Vec<(usize, usize)>,
    c: Vec<f64>,
    q: Vec<f64>,
    y: Vec<f64>,
    rotation: [[f64; 3]; 3],
}

impl<'a> Assembler<'a> {
    fn new(row: RowReader<'a>) -> Self {
        let spec = row.spec;
        let points = spec.tool_points.len().max(1);
        let (n, columns) = (spec.joint_columns.len(), spec.position_columns.len());
        // Task coordinates per data row: a pose's origin has 3, a point's columns come in turn.
        let m = if spec.orientation_columns.is_some() { columns } else { columns / points };
        Assembler {
            row,
            data: Measurements { order: spec.order, ..Measurements::with_points(n, m, points) },
            m,
            points,
            point_values: vec![0.0; m * points],
            lines: Vec::new(),
            seen: HashMap::new(),
            repeats: Vec::new(),
            c: vec![0.0; n],
            q: vec![0.0; n],
            y: vec![0.0; columns],
            rotation: [[0.0; 3]; 3],
        }
    }

    /// One row, at file `line` (for arrays: row + 2).
    fn add(&mut self, record: &dyn Row, line: u64) -> Result<(), ImportError> {
        let spec = self.row.spec;
        let (n, m, points) = (self.q.len(), self.m, self.points);
        self.row.convert(record, line, &mut self.c, &mut self.q, &mut self.y)?;
        if spec.orientation_columns.is_some() {
            self.row.rotation(record, line, &mut self.rotation)?;
            // y_j = p + R p_j (the measured pose read as its tool points).
            for (j, pj) in spec.tool_points.iter().chain(spec.tool_points.is_empty().then_some(&[0.0; 3])).enumerate() {
                self.point_values[3 * j..3 * j + 3].copy_from_slice(&crate::nominal::tool_points::point_of_pose(
                    &self.y,
                    &self.rotation,
                    pj,
                ));
            }
        } else {
            self.point_values.copy_from_slice(&self.y);
        }
        if let Some(frame) = &spec.planar_frame {
            frame.move_row(&mut self.q, &mut self.point_values);
        }
        // A repeat is a configuration measured twice: a file of targets or seeds alone has none.
        if n > 0 && m > 0 {
            let key: Vec<u64> = self.q.iter().map(|v| (v + 0.0).to_bits()).collect();
            match self.seen.get(&key) {
                Some(&first) => self.repeats.push((first, self.data.len())),
                None => {
                    self.seen.insert(key, self.data.len());
                }
            }
        }
        if m == 0 {
            // A file of joints alone (seeds, poses to measure).
            self.data.push(&self.q, &[]);
            self.lines.push(line);
        }
        for point in self.point_values.chunks_exact(m.max(1)).take(if m == 0 { 0 } else { points }) {
            self.data.push(&self.q, point);
            self.lines.push(line);
        }
        Ok(())
    }

    /// The measurements, once there are enough rows and no repeat contradicts another.
    fn finish(self) -> Result<ImportedMeasurements, ImportError> {
        let (spec, err, data, lines) = (self.row.spec, self.row.err, self.data, self.lines);
        if data.pose_count() < spec.min_rows.max(1) {
            return Err(err.at(None, None, format!("{} data rows; at least {} needed", data.pose_count(), spec.min_rows.max(1))));
        }
        let duplicates = check_repeats(&data, &lines, &self.repeats, spec, err)?;
        Ok(ImportedMeasurements { measurements: data, lines, duplicates })
    }
}

/// Largest measurement file read: 10⁷ rows of ten values; more would not fit a fit's memory anyway.
pub const MAX_CSV_BYTES: u64 = 1 << 30;

/// Longest line of a measurement file: a row of ten numbers is a few hundred bytes, a header of
/// long column names a few kilobytes.
pub const MAX_LINE_BYTES: usize = 64 << 10;

/// Refuses what is not CSV text before the CSV reader holds it as fields: a NUL byte (binary data)
/// or a line over [`MAX_LINE_BYTES`] (100 MB of NULs made one 100 MB field, 619 MB in all, and a
/// message quoting it whole). Names the line, and the column of a NUL.
fn check_text(bytes: &[u8], err: Errors<'_>) -> Result<(), ImportError> {
    for (k, line) in bytes.split(|&b| b == b'\n').enumerate() {
        let number = k as u64 + 1;
        if let Some(column) = line.iter().position(|&b| b == 0) {
            return Err(err.at(Some(number), None, format!("byte {} is NUL: binary data, not CSV text", column + 1)));
        }
        if line.len() > MAX_LINE_BYTES {
            return Err(err.at(
                Some(number),
                None,
                format!(
                    "the line is {} bytes long, more than the {} KiB a CSV line may be (not a measurement file?)",
                    line.len(),
                    MAX_LINE_BYTES >> 10
                ),
            ));
        }
    }
    Ok(())
}

/// What rows are read from, for messages: a CSV file (its lines) or arrays (their rows).
#[derive(Clone, Copy)]
enum Source<'a> {
    File(&'a Path),
    Rows(&'a str),
}

/// Builds the errors of one source.
#[derive(Clone, Copy)]
struct Errors<'a> {
    source: Source<'a>,
}

impl Errors<'_> {
    /// An error at file `line` (arrays: row + 2) and `column`.
    fn at(&self, line: Option<u64>, column: Option<&str>, message: String) -> ImportError {
        let column = column.map(str::to_string);
        match self.source {
            Source::File(file) => ImportError::Csv { file: file.to_path_buf(), line, column, message },
            Source::Rows(source) => {
                ImportError::Rows { source: source.to_string(), row: line.map(|l| l.saturating_sub(2)), column, message }
            }
        }
    }

    /// Where `line` is, in a message's words: `line 4`, or for arrays `row 2`.
    fn place(&self, line: u64) -> String {
        match self.source {
            Source::File(_) => format!("line {line}"),
            Source::Rows(_) => format!("row {}", line.saturating_sub(2)),
        }
    }
}

/// Turns one record into a joint configuration and a position in the model's units, checking
/// each value (a number, finite, in the joint's range, within [`MAX_MAGNITUDE`]).
struct RowReader<'a> {
    spec: &'a ColumnSpec,
    err: Errors<'a>,
    /// Record index of each joint column and each position column.
    joint_idx: Vec<usize>,
    pos_idx: Vec<usize>,
    /// Record index of each orientation column (a measured pose).
    orientation_idx: Vec<usize>,
    /// File unit → model unit, per joint and for lengths.
    joint_factor: Vec<f64>,
    length_factor: f64,
    /// The controller's values → model joints (the joint map, the units).
    columns: super::joint_columns::JointColumns<'a>,
}

impl<'a> RowReader<'a> {
    /// Finds the spec's columns in `header`: each must appear exactly once.
    fn new(header: &csv::StringRecord, spec: &'a ColumnSpec, err: Errors<'a>) -> Result<Self, ImportError> {
        let find = |name: &str| -> Result<usize, ImportError> {
            let hits: Vec<usize> = header.iter().enumerate().filter(|(_, h)| *h == name).map(|(i, _)| i).collect();
            match hits.as_slice() {
                [i] => Ok(*i),
                [] => {
                    // A header name that reads as `name` but holds a character that shows as nothing.
                    let visible = |h: &str| h.chars().filter(|&c| !crate::error::invisible(c)).collect::<String>();
                    if let Some((k, h)) = header.iter().enumerate().find(|(_, h)| *h != name && visible(h) == name) {
                        let c = h.chars().find(|&c| crate::error::invisible(c)).unwrap_or(' ');
                        return Err(err.at(
                            Some(1),
                            Some(name),
                            format!(
                                "no such column: header column {} is {} — `{name}` with the invisible character U+{:04X} in it; remove it",
                                k + 1,
                                crate::error::excerpt(h),
                                c as u32
                            ),
                        ));
                    }
                    Err(err.at(Some(1), Some(name), format!("no such column in the header (columns: {})", header_excerpt(header))))
                }
                _ => Err(err.at(Some(1), Some(name), "column name appears more than once in the header".into())),
            }
        };
        let joint_idx = spec.joint_columns.iter().map(|c| find(c)).collect::<Result<Vec<_>, _>>()?;
        let pos_idx = spec.position_columns.iter().map(|c| find(c)).collect::<Result<Vec<_>, _>>()?;
        let orientation_idx = spec.orientation_columns.iter().flat_map(|o| o.names()).map(|c| find(c)).collect::<Result<Vec<_>, _>>()?;
        let length_factor = spec.length_unit.factor_to(spec.model_length_unit);
        let columns = super::joint_columns::JointColumns::new(spec);
        let joint_factor = columns.factors().to_vec();
        Ok(RowReader { spec, err, joint_idx, pos_idx, orientation_idx, joint_factor, length_factor, columns })
    }

    /// The spec's columns in order, joints then positions then orientation: a row of numbers.
    fn in_order(spec: &'a ColumnSpec, err: Errors<'a>) -> Self {
        let n = spec.joint_columns.len();
        let p = spec.position_columns.len();
        let o = y_width(spec) - p;
        let columns = super::joint_columns::JointColumns::new(spec);
        RowReader {
            spec,
            err,
            joint_idx: (0..n).collect(),
            pos_idx: (n..n + p).collect(),
            orientation_idx: (n + p..n + p + o).collect(),
            joint_factor: columns.factors().to_vec(),
            length_factor: spec.length_unit.factor_to(spec.model_length_unit),
            columns,
        }
    }

    /// The measured pose's rotation at file `line`: from a quaternion (w, x, y, z) of norm 1 within
    /// [`ROTATION_TOLERANCE`], normalised, or a rotation matrix whose rows are orthonormal within it
    /// and whose determinant is positive.
    fn rotation(&self, record: &dyn Row, line: u64, r: &mut [[f64; 3]; 3]) -> Result<(), ImportError> {
        let Some(orientation) = &self.spec.orientation_columns else { return Ok(()) };
        let names = orientation.names();
        let mut v = [0.0; 9];
        for (k, (&idx, name)) in self.orientation_idx.iter().zip(names).enumerate() {
            v[k] = self.raw_value(record, line, idx, name)?;
        }
        let refuse = |message: String| self.err.at(Some(line), Some(&names.join(",")), message);
        match orientation {
            OrientationColumns::Quaternion(_) => {
                let norm = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2] + v[3] * v[3]).sqrt();
                if !((norm - 1.0).abs() <= ROTATION_TOLERANCE) {
                    return Err(refuse(format!("the quaternion's norm is {norm:.6}; a rotation's is 1 (within {ROTATION_TOLERANCE:e})")));
                }
                *r = crate::nominal::tool_points::rotation_of_quaternion([v[0] / norm, v[1] / norm, v[2] / norm, v[3] / norm]);
            }
            OrientationColumns::Rotation(_) => {
                *r = [[v[0], v[1], v[2]], [v[3], v[4], v[5]], [v[6], v[7], v[8]]];
                for i in 0..3 {
                    for j in 0..3 {
                        let dot: f64 = (0..3).map(|k| r[i][k] * r[j][k]).sum();
                        if !((dot - if i == j { 1.0 } else { 0.0 }).abs() <= ROTATION_TOLERANCE) {
                            return Err(refuse(format!("not a rotation: rows {} and {} have dot product {dot:.6}", i + 1, j + 1)));
                        }
                    }
                }
                let det = r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1]) - r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0])
                    + r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0]);
                if det <= 0.0 {
                    return Err(refuse(format!("not a rotation: determinant {det:.6} (a reflection)")));
                }
            }
        }
        Ok(())
    }

    /// The record at file `line` into `q` (model joints) and `y` (position); `c` holds the
    /// controller's joint values (the columns, in their units) on the way.
    fn convert(&self, record: &dyn Row, line: u64, c: &mut [f64], q: &mut [f64], y: &mut [f64]) -> Result<(), ImportError> {
        let spec = self.spec;
        for d in 0..q.len() {
            let unit = match spec.joint_kinds[d] {
                JointKind::Revolute => spec.angle_unit.name(),
                _ => spec.length_unit.name(),
            };
            let name = &spec.joint_columns[d];
            let idx = self.joint_idx[d];
            c[d] = self.raw_value(record, line, idx, name)?;
            let v = c[d] * self.joint_factor[d];
            // The joint's range first: it names the real cause (a unit or column mistake).
            let [lo, hi] = spec.joint_limits[d];
            if v.is_finite() && !(lo..=hi).contains(&v) {
                let f = self.joint_factor[d];
                return Err(self.err.at(
                    Some(line),
                    Some(name),
                    format!(
                        "{} {unit} is outside the joint's range [{}, {}] {unit} (wrong unit or column? {})",
                        record.field(idx).quoted(),
                        short(lo / f),
                        short(hi / f),
                        spec.range_hint
                    ),
                ));
            }
        }
        self.columns.mapped(c, q);
        for d in 0..q.len() {
            let units = match spec.joint_kinds[d] {
                JointKind::Revolute => (spec.angle_unit.name(), "rad"),
                _ => (spec.length_unit.name(), spec.model_length_unit.name()),
            };
            q[d] = self.bounded(record, line, q[d], self.joint_idx[d], &spec.joint_columns[d], units)?;
        }
        for c in 0..y.len() {
            let name = &spec.position_columns[c];
            let v = self.raw_value(record, line, self.pos_idx[c], name)? * self.length_factor;
            let units = (spec.length_unit.name(), spec.model_length_unit.name());
            y[c] = self.bounded(record, line, v, self.pos_idx[c], name, units)?;
        }
        Ok(())
    }

    /// A field parsed as a number; finiteness is checked again after conversion ([`Self::bounded`]).
    /// The field's text is only copied into an error message, never per value (10⁶-row files).
    fn raw_value(&self, record: &dyn Row, line: u64, idx: usize, name: &str) -> Result<f64, ImportError> {
        let text = match record.field(idx) {
            Field::Number(v) if v.is_finite() => return Ok(v),
            Field::Number(v) => return Err(self.err.at(Some(line), Some(name), format!("not a finite number: '{v:?}'"))),
            Field::Text(text) => text,
        };
        if text.is_empty() {
            return Err(self.err.at(Some(line), Some(name), "missing value".into()));
        }
        let quoted = || crate::error::excerpt(text);
        let v: f64 = text.parse().map_err(|_| self.err.at(Some(line), Some(name), format!("not a number: '{}'", quoted())))?;
        if !v.is_finite() {
            return Err(self.err.at(Some(line), Some(name), format!("not a finite number: '{}'", quoted())));
        }
        Ok(v)
    }

    /// A value converted to the model's unit must be finite and within MAX_MAGNITUDE *after* the
    /// conversion (1e307 m is finite, 1e310 mm is not), so nothing non-finite gets past the reader.
    /// `units`: the file's unit and the model's, for the message.
    fn bounded(&self, record: &dyn Row, line: u64, v: f64, idx: usize, name: &str, units: (&str, &str)) -> Result<f64, ImportError> {
        if v.abs() <= MAX_MAGNITUDE {
            return Ok(v);
        }
        let (unit, model_unit) = units;
        let in_model = if v.is_finite() { format!("{v:e} {model_unit}") } else { format!("beyond the largest number in {model_unit}") };
        Err(self.err.at(
            Some(line),
            Some(name),
            format!(
                "'{}' {unit} is {in_model}; values must stay within ±{MAX_MAGNITUDE:e} in the model's unit (wrong unit or column?)",
                record.field(idx).quoted()
            ),
        ))
    }
}

/// The repeated joint configurations (`repeats`: first row, repeating row) as duplicates, or an
/// error at the first whose positions differ by more than the repeat tolerance.
fn check_repeats(
    data: &Measurements,
    lines: &[u64],
    repeats: &[(usize, usize)],
    spec: &ColumnSpec,
    err: Errors<'_>,
) -> Result<Vec<Duplicate>, ImportError> {
    let tolerance = spec.repeat_tolerance.unwrap_or_else(|| 1e-3 * data.bounding_box_diagonal());
    let mut duplicates = Vec::new();
    let points = data.points_per_pose.max(1);
    for &(first, row) in repeats {
        // The farthest of the pose's points (a repeat of a pose repeats all of them).
        let distance = (0..points)
            .map(|j| data.position(first + j).iter().zip(data.position(row + j)).map(|(a, b)| (a - b) * (a - b)).sum::<f64>().sqrt())
            .fold(0.0, f64::max);
        let (line, first_line) = (lines[row], lines[first]);
        if distance > tolerance {
            return Err(err.at(
                Some(line),
                None,
                format!(
                    "contradictory measurements: the joint configuration repeats {} but the positions are {distance:.3e} {} apart (repeat tolerance {tolerance:.3e}; set `repeat_tolerance` in [measurements] if the robot really is that unrepeatable)",
                    err.place(first_line),
                    spec.model_length_unit.name()
                ),
            ));
        }
        duplicates.push(Duplicate { line, first_line, distance });
    }
    Ok(duplicates)
}

/// File lines of record starts, counted incrementally: the csv reader hands out records in file
/// order, so counting from the previous record instead of from the file's start keeps the import
/// linear in the file (counting from the start made 10⁵ rows take minutes).
struct LineCounter<'a> {
    bytes: &'a [u8],
    /// Bytes before `pos` are counted.
    pos: usize,
    /// Newlines in `bytes[..pos]`.
    newlines: u64,
}

impl<'a> LineCounter<'a> {
    fn new(bytes: &'a [u8]) -> Self {
        LineCounter { bytes, pos: 0, newlines: 0 }
    }

    /// 1-based line of the record starting at byte `start`. The csv crate's own line count is one
    /// short after a CRLF line end (a record may start at the LF), so count from the bytes themselves.
    fn line_at(&mut self, start: u64) -> u64 {
        let mut end = usize::try_from(start).unwrap_or(usize::MAX).min(self.bytes.len());
        while end < self.bytes.len() && (self.bytes[end] == b'\r' || self.bytes[end] == b'\n') {
            end += 1;
        }
        if end < self.pos {
            // Not expected (positions only grow); recount rather than give a wrong line.
            *self = LineCounter::new(self.bytes);
        }
        self.newlines += self.bytes[self.pos..end].iter().filter(|&&b| b == b'\n').count() as u64;
        self.pos = end;
        1 + self.newlines
    }
}

/// The header's column names for a message: each an excerpt, at most the first 20.
fn header_excerpt(header: &csv::StringRecord) -> String {
    let mut names: Vec<String> = header.iter().take(20).map(crate::error::excerpt).collect();
    if header.len() > 20 {
        names.push(format!("… {} columns in all", header.len()));
    }
    names.join(", ")
}

/// A limit converted back to the file's unit, without the conversion's rounding noise.
fn short(v: f64) -> String {
    let text = format!("{v:.9}");
    let text = text.trim_end_matches('0').trim_end_matches('.');
    if text == "-0" {
        "0".into()
    } else {
        text.into()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::units::{AngleUnit, LengthUnit};

    fn spec() -> ColumnSpec {
        ColumnSpec {
            joint_columns: vec!["q1".into(), "s2".into()],
            position_columns: vec!["x".into(), "y".into(), "z".into()],
            joint_kinds: vec![JointKind::Revolute, JointKind::Prismatic],
            angle_unit: AngleUnit::Deg,
            length_unit: LengthUnit::Mm,
            model_length_unit: LengthUnit::M,
            min_rows: 2,
            joint_limits: default_joint_limits(&[JointKind::Revolute, JointKind::Prismatic]),
            repeat_tolerance: None,
            joint_map: None,
            planar_frame: None,
            tool_points: Vec::new(),
            orientation_columns: None,
            order: crate::data::RowOrder::Measured,
            range_hint: RANGE_FROM_MODEL_FILE,
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

    /// Issue 51 class 6: a header name with a character that shows as nothing is named as such.
    #[test]
    fn a_header_name_with_an_invisible_character_is_named() {
        let (line, column, message) = csv_err("z,x,y,s2,q1\u{200b}\n3,1,2,500,180\n");
        assert_eq!((line, column.as_deref()), (Some(1), Some("q1")));
        assert!(message.contains("header column 5 is q1\\u{200b}") && message.contains("invisible character U+200B"), "{message}");
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
    fn first_data_row_is_line_2() {
        let (line, col, _) = csv_err("q1,s2,x,y,z\n1,2,,4,5\n1,2,3,4,5\n");
        assert_eq!((line, col.as_deref()), (Some(2), Some("x")));
        // Windows line ends count the same.
        let (line, _, _) = csv_err("q1,s2,x,y,z\r\n1,2,,4,5\r\n1,2,3,4,5\r\n");
        assert_eq!(line, Some(2));
        let (line, _, _) = csv_err("q1,s2,x,y,z\r\n1,2,3,4,5\r\n1,2,,4,5\r\n");
        assert_eq!(line, Some(3));
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
        // Positions in mm, model in m: rows 2 and 4 are 0.001 mm apart, the box diagonal ~10 mm.
        let r = read("q1,s2,x,y,z\n1,2,3,4,5\n7,8,9,9,9\n1,2,3.001,4,5\n").unwrap();
        assert_eq!(r.measurements.len(), 3);
        assert_eq!((r.duplicates.len(), r.duplicates[0].line, r.duplicates[0].first_line), (1, 4, 2));
        assert!((r.duplicates[0].distance - 1e-6).abs() < 1e-12);
        let w = r.warnings(Path::new("meas.csv"));
        assert_eq!(w, vec!["meas.csv:4: joint configuration repeats line 2 (positions 1.000e-6 apart)".to_string()]);
    }

    /// Messages, issue 27: one warning per repeated row (99 998 lines for a 100 k-row file); the
    /// first few are listed, the rest counted on one line.
    #[test]
    fn many_duplicates_are_summarised() {
        let text = format!("q1,s2,x,y,z\n{}", "1,2,3,4,5\n".repeat(1000));
        let w = read(&text).unwrap().warnings(Path::new("meas.csv"));
        assert_eq!(w.len(), DUPLICATES_LISTED + 1, "{w:?}");
        assert_eq!(
            w[DUPLICATES_LISTED],
            "meas.csv: 994 more rows repeat an earlier joint configuration (999 in all, positions at most 0.000e0 apart); all are kept"
        );
    }

    /// Issue 27 item 10: 100 MB of NUL bytes became one 100 MB header field (619 MB RSS) echoed whole
    /// in the error; a 300 MB field gave 300 MB of stderr. Binary data and overlong lines are refused
    /// before the CSV reader, and every quoted field is an excerpt.
    #[test]
    fn binary_data_and_overlong_lines_are_refused_and_fields_quoted_short() {
        let (line, _, msg) = csv_err(&"\0".repeat(1 << 20));
        assert_eq!((line, msg.as_str()), (Some(1), "byte 1 is NUL: binary data, not CSV text"));
        let (line, _, msg) = csv_err(&format!("q1,s2,x,y,z\n1,2,3,4,5\n1,{},3,4,5\n", "9".repeat(MAX_LINE_BYTES)));
        assert!(line == Some(3) && msg.contains("65544 bytes long, more than the 64 KiB"), "{msg}");
        let field = "x".repeat(5000);
        let (_, _, msg) = csv_err(&format!("q1,s2,x,y,z\n1,2,{field},4,5\n"));
        assert!(msg.len() < 120 && msg.contains("… (5000 bytes)"), "{msg}");
        let header = (0..500).map(|k| format!("c{k}{}", "y".repeat(100))).collect::<Vec<_>>().join(",");
        let (_, _, msg) = csv_err(&format!("{header}\n"));
        assert!(msg.len() < 2000 && msg.contains("500 columns in all"), "{}", msg.len());
        let mut big = std::io::Read::chain(&b"q1,s2,x,y,z\n"[..], std::io::repeat(b'\n'));
        let e = read_measurements_from(&mut big, Path::new("endless.csv"), &spec()).unwrap_err().to_string();
        assert!(e.contains("larger than 1024 MiB"), "{e}");
    }

    #[test]
    fn contradictory_repeats_are_errors_naming_both_lines() {
        let (line, col, msg) = csv_err("q1,s2,x,y,z\n1,2,3,4,5\n7,8,9,9,9\n1,2,3.5,4,5\n");
        assert_eq!((line, col), (Some(4), None));
        assert!(msg.contains("contradictory") && msg.contains("repeats line 2") && msg.contains("5.000e-4 m apart"), "{msg}");
        // A declared tolerance admits them.
        let spec = ColumnSpec { repeat_tolerance: Some(1e-3), ..spec() };
        let r = read_measurements_from("q1,s2,x,y,z\n1,2,3,4,5\n7,8,9,9,9\n1,2,3.5,4,5\n".as_bytes(), Path::new("m.csv"), &spec).unwrap();
        assert_eq!(r.duplicates.len(), 1);
    }

    #[test]
    fn joint_values_outside_the_range_name_line_column_and_range() {
        let (line, col, msg) = csv_err("q1,s2,x,y,z\n1,2,3,4,5\n400,2,3,4,5\n");
        assert_eq!((line, col.as_deref()), (Some(3), Some("q1")));
        assert!(msg.contains("400 deg is outside the joint's range [-360, 360] deg"), "{msg}");
        assert!(csv_err("q1,s2,x,y,z\n1,2,3,4,5\n1e300,2,3,4,5\n").2.contains("outside"));
        // Prismatic joints have no default range; a declared one is enforced in the file's unit.
        assert!(read("q1,s2,x,y,z\n1,2e6,3,4,5\n7,8,9,9,9\n").is_ok());
        let spec = ColumnSpec { joint_limits: vec![[-1.0, 1.0], [0.0, 0.5]], ..spec() };
        let e = read_measurements_from("q1,s2,x,y,z\n1,600,3,4,5\n7,8,9,9,9\n".as_bytes(), Path::new("m.csv"), &spec).unwrap_err();
        assert!(e.to_string().contains("m.csv:2: column 's2': 600 mm is outside the joint's range [0, 500] mm"), "{e}");
    }

    /// Issue 17 item 1: the line of each record was counted from the file's start (quadratic: 10⁵
    /// rows took about three minutes). 10⁵ rows must now take well under a second; 5 s leaves room
    /// for a loaded 2-core machine.
    #[test]
    fn csv_import_is_linear_in_rows() {
        let rows = 100_000;
        let mut text = String::from("q1,s2,x,y,z\n");
        for i in 0..rows {
            text.push_str(&format!("{},{},{},{},{}\n", (i % 720) as f64 * 0.5 - 180.0, i, i % 97, i % 89, i % 83));
        }
        let start = std::time::Instant::now();
        let r = read(&text).unwrap();
        let seconds = start.elapsed().as_secs_f64();
        assert_eq!(r.measurements.len(), rows);
        assert_eq!((r.lines[0], r.lines[rows - 1]), (2, rows as u64 + 1));
        assert!(seconds < 5.0, "{rows} rows imported in {seconds:.1} s");
    }

    #[test]
    fn line_counter_counts_each_record_once_and_handles_crlf() {
        let bytes = b"h\r\na\r\n\r\nb\nc";
        let mut lines = LineCounter::new(bytes);
        assert_eq!([lines.line_at(0), lines.line_at(3), lines.line_at(8), lines.line_at(10)], [1, 2, 4, 5]);
        // A position behind the cursor (not produced by the csv reader) is recounted, not misnumbered.
        assert_eq!(lines.line_at(3), 2);
    }

    /// Issue 17 item 2: finiteness was checked before the unit conversion, so 1e307 m in a
    /// model in mm was imported as +inf. Now the converted value is checked, naming line and column.
    #[test]
    fn finiteness_is_checked_after_unit_conversion() {
        let spec = ColumnSpec { length_unit: LengthUnit::M, model_length_unit: LengthUnit::Mm, ..spec() };
        let text = "q1,s2,x,y,z\n1,2,3,4,5\n1,2,3,1e307,5\n";
        let e = read_measurements_from(text.as_bytes(), Path::new("m.csv"), &spec).unwrap_err();
        let ImportError::Csv { line, column, message, .. } = &e else { panic!("{e}") };
        assert_eq!((*line, column.as_deref()), (Some(3), Some("y")), "{e}");
        assert!(message.contains("'1e307' m") && message.contains("beyond"), "{message}");
        // A prismatic joint the same way (no default range to catch it).
        let text = "q1,s2,x,y,z\n1,1e306,3,4,5\n1,2,3,4,5\n";
        let e = read_measurements_from(text.as_bytes(), Path::new("m.csv"), &spec).unwrap_err().to_string();
        assert!(e.starts_with("m.csv:2: column 's2': '1e306' m"), "{e}");
        // Finite but absurd (its square overflows downstream): refused as well.
        let (line, col, msg) = csv_err("q1,s2,x,y,z\n1,2,3,4,5\n1,2,3,4,1e200\n");
        assert_eq!((line, col.as_deref()), (Some(3), Some("z")));
        assert!(msg.contains("1e197 m") && msg.contains("1e100"), "{msg}");
        // Every imported value is finite and bounded.
        let r = read("q1,s2,x,y,z\n1,2,3,4,5\n7,8,3,4,1e100\n").unwrap();
        assert!(r.measurements.positions.iter().all(|v| v.abs() <= MAX_MAGNITUDE));
    }

    /// Issue 17 item 7: a joint value of 1e308 was printed as a 309-digit number; the message now
    /// quotes the file's text.
    #[test]
    fn joint_value_1e308_is_printed_as_written() {
        let (line, col, msg) = csv_err("q1,s2,x,y,z\n1,2,3,4,5\n1e308,2,3,4,5\n");
        assert_eq!((line, col.as_deref()), (Some(3), Some("q1")));
        assert!(msg.starts_with("'1e308' deg is") || msg.starts_with("1e308 deg is outside"), "{msg}");
        assert!(msg.len() < 200, "{msg}");
    }

    /// Issue 52: rows of numbers are the CSV's rows — the same measurements, lines and repeats, by
    /// the same checks — and a fault names the arrays, the row and the column.
    #[test]
    fn rows_of_numbers_are_read_as_the_csv() {
        let text = "q1,s2,x,y,z\n180,500,1,2,3\n-90,-250,10,20,30\n180,500,1.001,2,3\n";
        let q = [180.0, 500.0, -90.0, -250.0, 180.0, 500.0];
        let y = [1.0, 2.0, 3.0, 10.0, 20.0, 30.0, 1.001, 2.0, 3.0];
        let rows = measurements_from_rows("(q, y)", &q, &y, 3, &spec()).unwrap();
        assert_eq!(rows, read(text).unwrap());
        let bad = [180.0, 500.0, -90.0, f64::NAN, 180.0, 500.0];
        let e = measurements_from_rows("(q, y)", &bad, &y, 3, &spec()).unwrap_err().to_string();
        assert_eq!(e, "(q, y) row 1: column 's2': not a finite number: 'NaN'");
        let far = [180.0, 500.0, 400.0, -250.0, 180.0, 500.0];
        let e = measurements_from_rows("(q, y)", &far, &y, 3, &spec()).unwrap_err().to_string();
        assert!(e.starts_with("(q, y) row 1: column 'q1': 400.0 deg is outside the joint's range [-360, 360] deg"), "{e}");
        let e = measurements_from_rows("(q, y)", &q[..2], &y[..3], 1, &spec()).unwrap_err().to_string();
        assert_eq!(e, "(q, y): 1 data rows; at least 2 needed");
        let y_far = [1.0, 2.0, 3.0, 10.0, 20.0, 30.0, 1.5, 2.0, 3.0];
        let e = measurements_from_rows("(q, y)", &q, &y_far, 3, &spec()).unwrap_err().to_string();
        assert!(e.starts_with("(q, y) row 2: contradictory measurements: the joint configuration repeats row 0"), "{e}");
    }

    #[test]
    fn missing_file_is_an_io_error_naming_it() {
        let e = read_measurements("/nonexistent/dir/m.csv", &spec()).unwrap_err();
        assert!(matches!(e, ImportError::Io { .. }) && e.to_string().contains("/nonexistent/dir/m.csv"));
    }
}

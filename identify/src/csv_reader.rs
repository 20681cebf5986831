//! CSV files with one header line: time in column `t`, channels matched by name,
//! unit suffixes (`alpha[deg]`) converted to SI, extra columns kept.

use std::path::Path;

use crate::data::{
    experiment_name, sampling_warning, Channel, ChannelSpec, Experiment, MIN_SAMPLES,
};
use crate::error::{CellProblem, DataError, DataWarning};
use crate::units::{lookup_unit, split_header, Kind};

/// How one column is read.
struct ColumnPlan {
    /// 0-based field index.
    index: usize,
    /// Channel name.
    name: String,
    /// Full header.
    header: String,
    /// Factor to SI.
    factor: f64,
    /// Unit note for the channel.
    note: Option<String>,
    /// Needed (time or in the spec): bad cells are errors. Otherwise bad cells drop it.
    needed: bool,
}

/// Reads a CSV experiment. See [`crate::read_experiment`].
pub(crate) fn read_csv(
    path: &Path,
    spec: &ChannelSpec,
) -> Result<(Experiment, Vec<DataWarning>), DataError> {
    let file = path.to_path_buf();
    let io_err = |e: std::io::Error| DataError::Io {
        file: file.clone(),
        message: e.to_string(),
    };
    let reader = std::fs::File::open(path).map_err(io_err)?;
    let mut rdr = csv::ReaderBuilder::new()
        .flexible(true)
        .trim(csv::Trim::All)
        .comment(Some(b'#'))
        .from_reader(LineCap::new(std::io::BufReader::new(reader)));
    let csv_err = |e: csv::Error| DataError::Csv {
        file: file.clone(),
        line: e.position().map(|p| p.line()),
        message: match e.kind() {
            csv::ErrorKind::Io(io) if io.kind() == std::io::ErrorKind::InvalidData => {
                io.to_string()
            }
            _ => e.to_string(),
        },
    };
    let headers = rdr.headers().map_err(csv_err)?.clone();
    let mut warnings = Vec::new();

    // Header names without suffixes, duplicates rejected.
    let split: Vec<(String, Option<String>)> = headers
        .iter()
        .map(|h| {
            let (n, u) = split_header(h);
            (n.to_string(), u.map(str::to_string))
        })
        .collect();
    for (j, (name, _)) in split.iter().enumerate() {
        if let Some(i) = split[..j].iter().position(|(n, _)| n == name) {
            if name.is_empty() {
                continue;
            }
            return Err(DataError::DuplicateColumn {
                file,
                column: name.clone(),
                first: i + 1,
                second: j + 1,
            });
        }
    }
    let found: Vec<String> = split.iter().map(|(n, _)| n.clone()).collect();

    // Plan the needed columns: time, then the spec's channels.
    let needed: Vec<(String, Kind)> = std::iter::once(("t".to_string(), Kind::Time))
        .chain(spec.all().cloned())
        .collect();
    let mut plans: Vec<ColumnPlan> = Vec::new();
    let plan = |index: usize, name: &str, kind: Kind| -> Result<ColumnPlan, DataError> {
        let header = headers.get(index).unwrap_or_default().to_string();
        let (factor, note) =
            unit_factor(&file, index + 1, &header, split[index].1.as_deref(), kind)?;
        Ok(ColumnPlan {
            index,
            name: name.to_string(),
            header,
            factor,
            note,
            needed: true,
        })
    };
    for (name, kind) in &needed {
        let Some(index) = found.iter().position(|n| n == name) else {
            return Err(DataError::MissingColumn {
                file: file.clone(),
                column: name.clone(),
                found,
                expected: spec.expected_names(),
            });
        };
        plans.push(plan(index, name, *kind)?);
    }
    // Optional channels when present.
    for (name, kind) in &spec.optional {
        let Some(index) = found.iter().position(|n| n == name) else {
            continue;
        };
        if plans.iter().any(|p| p.index == index) {
            continue;
        }
        plans.push(plan(index, name, *kind)?);
    }
    // Extra columns, in file order.
    for (index, (name, unit)) in split.iter().enumerate() {
        if plans.iter().any(|p| p.index == index) || name.is_empty() {
            continue;
        }
        let header = headers.get(index).unwrap_or_default().to_string();
        let (factor, note) = match unit {
            None => (1.0, None),
            Some(u) => match lookup_unit(u) {
                Some(unit) => (unit.factor, Some(unit_note(u, unit.kind))),
                None => {
                    warnings.push(DataWarning::UnknownExtraUnit {
                        file: file.clone(),
                        column: header.clone(),
                    });
                    (1.0, Some(u.clone()))
                }
            },
        };
        plans.push(ColumnPlan {
            index,
            name: name.clone(),
            header,
            factor,
            note,
            needed: false,
        });
    }

    // Read the rows.
    let t_col = plans[0].index;
    let mut values: Vec<Vec<f64>> = vec![Vec::new(); plans.len()];
    let mut dropped: Vec<Option<u64>> = vec![None; plans.len()];
    let mut record = csv::StringRecord::new();
    let width = headers.len();
    // (row index, line) wherever the line stops being row index + 2
    // (comment or blank lines): the line of any row, without a line per row
    let mut line_breaks: Vec<(usize, u64)> = Vec::new();
    loop {
        match rdr.read_record(&mut record) {
            Ok(true) => {}
            Ok(false) => break,
            Err(e) => return Err(csv_err(e)),
        }
        let line = record.position().map(|p| p.line()).unwrap_or(0);
        let row = values[0].len();
        let expected = line_breaks
            .last()
            .map_or(row as u64 + 2, |&(r, l)| l + (row - r) as u64);
        if line != expected {
            line_breaks.push((row, line));
        }
        if record.len() != width {
            return Err(DataError::FieldCount {
                file,
                line,
                expected: width,
                found: record.len(),
                decimal_comma: if record.len() > width {
                    decimal_comma(&record)
                } else {
                    None
                },
            });
        }
        for (k, plan) in plans.iter().enumerate() {
            let cell = record.get(plan.index).unwrap_or("");
            let parsed = parse_cell(cell).and_then(|v| {
                if (v * plan.factor).abs() <= crate::data::MAX_ABS_VALUE {
                    Ok(v)
                } else {
                    Err(CellProblem::TooLarge(cell.trim().to_string()))
                }
            });
            match parsed {
                Ok(v) => values[k].push(v * plan.factor),
                Err(problem) if plan.needed => {
                    return Err(DataError::BadCell {
                        file,
                        line,
                        column: plan.index + 1,
                        column_name: plan.header.clone(),
                        problem,
                    })
                }
                Err(_) => {
                    if dropped[k].is_none() {
                        dropped[k] = Some(line);
                    }
                    values[k].push(f64::NAN);
                }
            }
        }
        // Time must strictly increase (checked in file order).
        let t = &values[0];
        let n = t.len();
        if n >= 2 && t[n - 1] <= t[n - 2] {
            return Err(DataError::TimeNotIncreasing {
                file,
                line,
                column: t_col + 1,
                previous: t[n - 2],
                value: t[n - 1],
            });
        }
    }
    let n = values[0].len();
    if n < MIN_SAMPLES {
        return Err(DataError::TooShort {
            file,
            samples: n,
            minimum: MIN_SAMPLES,
        });
    }

    if let Some((sample, median_dt)) = crate::data::first_gap(&values[0]) {
        let line = line_breaks
            .iter()
            .rev()
            .find(|&&(r, _)| r <= sample)
            .map_or(sample as u64 + 2, |&(r, l)| l + (sample - r) as u64);
        return Err(DataError::TimeGap {
            file,
            line: Some(line),
            sample: sample + 1,
            from: values[0][sample - 1],
            to: values[0][sample],
            median_dt,
        });
    }
    let mut columns = values.into_iter();
    let t = columns.next().unwrap_or_default();
    let mut channels = Vec::new();
    for (k, (plan, vals)) in plans
        .iter()
        .zip(std::iter::once(Vec::new()).chain(columns))
        .enumerate()
    {
        if k == 0 {
            continue;
        }
        if let Some(line) = dropped[k] {
            warnings.push(DataWarning::DroppedColumn {
                file: file.clone(),
                column: plan.header.clone(),
                line,
            });
            continue;
        }
        channels.push(Channel {
            name: plan.name.clone(),
            unit_note: plan.note.clone(),
            values: vals,
        });
    }
    warnings.extend(sampling_warning(&file, &t));
    if plans[0].note.is_none() {
        warnings.extend(crate::plausibility::time_unit_warning(&file, &t));
    }
    Ok((
        Experiment {
            name: experiment_name(path),
            file,
            t,
            channels,
        },
        warnings,
    ))
}

/// Longest CSV line read: 1 MiB. A row of numbers is under 1 KB (20
/// columns of 24 characters) and a header of 1000 named columns under
/// 64 KB; a file without line ends (or of NUL bytes) would otherwise be read
/// into one record of its whole size.
pub const MAX_LINE_BYTES: usize = 1 << 20;

/// A reader that fails ([`std::io::ErrorKind::InvalidData`]) once a line
/// runs longer than [`MAX_LINE_BYTES`].
struct LineCap<R> {
    inner: R,
    since_newline: usize,
}

impl<R> LineCap<R> {
    fn new(inner: R) -> Self {
        Self {
            inner,
            since_newline: 0,
        }
    }
}

impl<R: std::io::Read> std::io::Read for LineCap<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        match buf[..n].iter().rposition(|&b| b == b'\n') {
            Some(i) => self.since_newline = n - i - 1,
            None => self.since_newline += n,
        }
        if self.since_newline > MAX_LINE_BYTES {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!(
                    "a line longer than {} MiB: not a CSV recording (rows of numbers end with a line break)",
                    MAX_LINE_BYTES >> 20
                ),
            ));
        }
        Ok(n)
    }
}

/// The factor to SI and the unit note of a column with unit suffix `unit`
/// (none: factor 1, no note), checked against the channel's `kind`; errors
/// name `column` (1-based) and its full `header`.
pub(crate) fn unit_factor(
    file: &Path,
    column: usize,
    header: &str,
    unit: Option<&str>,
    kind: Kind,
) -> Result<(f64, Option<String>), DataError> {
    let Some(u) = unit else {
        return Ok((1.0, None));
    };
    match lookup_unit(u) {
        None => Err(DataError::UnknownUnit {
            file: file.to_path_buf(),
            column,
            header: header.to_string(),
            unit: u.to_string(),
            kind,
        }),
        Some(unit) if kind != Kind::Other && unit.kind != kind => {
            Err(DataError::IncompatibleUnit {
                file: file.to_path_buf(),
                column,
                header: header.to_string(),
                unit: u.to_string(),
                expected: kind,
                found: unit.kind,
            })
        }
        Some(unit) => Ok((unit.factor, Some(unit_note(u, unit.kind)))),
    }
}

/// The unit note for a suffix: `rad` for SI, `deg -> rad` for a conversion.
pub(crate) fn unit_note(symbol: &str, kind: Kind) -> String {
    let si = kind.si_unit();
    if symbol == si || si.is_empty() {
        symbol.to_string()
    } else {
        format!("{symbol} -> {si}")
    }
}

/// The first pair of adjacent fields that reads like one number written
/// with a decimal comma (`3` and `14`, or `-0` and `5e-3`): (1-based column
/// of the first, `3,14`).
fn decimal_comma(record: &csv::StringRecord) -> Option<(usize, String)> {
    let int = |s: &str| {
        let s = s.strip_prefix(['-', '+']).unwrap_or(s);
        !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit())
    };
    let frac = |s: &str| {
        let digits = s.bytes().take_while(u8::is_ascii_digit).count();
        digits > 0
            && (digits == s.len()
                || (matches!(s.as_bytes()[digits], b'e' | b'E')
                    && s[digits + 1..].parse::<i32>().is_ok()))
    };
    let cells: Vec<&str> = record.iter().collect();
    cells
        .windows(2)
        .position(|w| int(w[0]) && frac(w[1]))
        .map(|j| (j + 1, format!("{},{}", cells[j], cells[j + 1])))
}

/// Parses one cell as a finite number.
fn parse_cell(cell: &str) -> Result<f64, CellProblem> {
    let s = cell.trim();
    if s.is_empty() {
        return Err(CellProblem::Empty);
    }
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err(CellProblem::NotFinite(s.to_string())),
        Err(_) => Err(CellProblem::Unparsable(s.to_string())),
    }
}

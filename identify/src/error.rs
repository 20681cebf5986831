//! Errors and warnings raised while reading measurement files.
//!
//! Every error names the file and, where it has one, the line (1-based, the
//! header is line 1) and the column (1-based field index, plus its header name).
//! `Display` prints `file:line:column: message` followed by a `help:` line.

use std::fmt;
use std::path::PathBuf;

/// What is wrong with one cell of a CSV file.
#[derive(Clone, Debug, PartialEq)]
pub enum CellProblem {
    /// The cell is empty (or the row is too short to have it).
    Empty,
    /// The cell holds NaN or an infinity.
    NotFinite(String),
    /// The cell is not a number.
    Unparsable(String),
    /// The value (in SI units) is beyond [`crate::data::MAX_ABS_VALUE`].
    TooLarge(String),
}

/// A measurement file that cannot be used. Fields name the place of the problem.
#[derive(Clone, Debug, PartialEq)]
pub enum DataError {
    /// The file cannot be opened or read.
    Io {
        /// The file.
        file: PathBuf,
        /// The operating system's message.
        message: String,
    },
    /// The CSV structure itself is broken (e.g. bad quoting, invalid UTF-8).
    Csv {
        /// The file.
        file: PathBuf,
        /// The line, if known.
        line: Option<u64>,
        /// The parser's message.
        message: String,
    },
    /// A channel the model needs has no column.
    MissingColumn {
        /// The file.
        file: PathBuf,
        /// The missing channel (`t` for time).
        column: String,
        /// The header names found in the file (unit suffixes removed).
        found: Vec<String>,
        /// The channel names the model expects, time first.
        expected: Vec<String>,
    },
    /// Two columns carry the same name.
    DuplicateColumn {
        /// The file.
        file: PathBuf,
        /// The name.
        column: String,
        /// 1-based index of the first column.
        first: usize,
        /// 1-based index of the second column.
        second: usize,
    },
    /// A cell of a needed column is empty, NaN/infinite or not a number.
    BadCell {
        /// The file.
        file: PathBuf,
        /// The line (header is line 1).
        line: u64,
        /// 1-based column index.
        column: usize,
        /// The column's header.
        column_name: String,
        /// What is wrong.
        problem: CellProblem,
    },
    /// Time does not strictly increase.
    TimeNotIncreasing {
        /// The file.
        file: PathBuf,
        /// The line of the offending sample.
        line: u64,
        /// 1-based column index of time.
        column: usize,
        /// Previous time (s).
        previous: f64,
        /// This time (s).
        value: f64,
    },
    /// One sampling interval is longer than [`crate::data::MAX_GAP_INTERVALS`]
    /// median intervals: a gap in the recording, or a wrong stamp.
    TimeGap {
        /// The file.
        file: PathBuf,
        /// The line of the sample after the gap (text files).
        line: Option<u64>,
        /// 1-based index of the sample after the gap.
        sample: usize,
        /// Time before the gap (s).
        from: f64,
        /// Time after the gap (s).
        to: f64,
        /// The median sampling interval (s).
        median_dt: f64,
    },
    /// Fewer samples than the minimum.
    TooShort {
        /// The file.
        file: PathBuf,
        /// Samples found.
        samples: usize,
        /// Minimum accepted.
        minimum: usize,
    },
    /// A header carries a unit suffix that is not known.
    UnknownUnit {
        /// The file.
        file: PathBuf,
        /// 1-based column index.
        column: usize,
        /// The full header.
        header: String,
        /// The suffix.
        unit: String,
        /// The kind of the channel, which decides the accepted units.
        kind: crate::units::Kind,
    },
    /// A known unit of the wrong kind (`theta[mm]`).
    IncompatibleUnit {
        /// The file.
        file: PathBuf,
        /// 1-based column index.
        column: usize,
        /// The full header.
        header: String,
        /// The suffix.
        unit: String,
        /// The kind the channel should have.
        expected: crate::units::Kind,
        /// The kind the unit measures.
        found: crate::units::Kind,
    },
    /// A MAT file that cannot be used.
    Mat {
        /// The file.
        file: PathBuf,
        /// What is wrong.
        message: String,
        /// How to fix it.
        help: String,
    },
    /// A bad channel mapping argument (`--channels theta,alpha,Vm`).
    ChannelMap {
        /// What is wrong.
        message: String,
    },
    /// A row has more (or fewer) fields than the header: a decimal comma
    /// (`3,14`) or a stray separator would shift every later cell.
    FieldCount {
        /// The file.
        file: PathBuf,
        /// The line (header is line 1).
        line: u64,
        /// Fields in the header.
        expected: usize,
        /// Fields in this row.
        found: usize,
        /// A pair of fields that reads like a number with a decimal comma:
        /// (1-based column of its first part, the text `3,14`).
        decimal_comma: Option<(usize, String)>,
    },
    /// The file extension is neither `.csv` nor `.mat`.
    UnknownFormat {
        /// The file.
        file: PathBuf,
    },
}

/// Whether a data file is a text (CSV) file, whose errors have lines.
fn is_text(file: &std::path::Path) -> bool {
    !file
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("mat"))
}

impl DataError {
    /// The file concerned, if any.
    pub fn file(&self) -> Option<&std::path::Path> {
        use DataError::*;
        match self {
            Io { file, .. }
            | Csv { file, .. }
            | MissingColumn { file, .. }
            | DuplicateColumn { file, .. }
            | BadCell { file, .. }
            | TimeNotIncreasing { file, .. }
            | TimeGap { file, .. }
            | TooShort { file, .. }
            | UnknownUnit { file, .. }
            | IncompatibleUnit { file, .. }
            | Mat { file, .. }
            | FieldCount { file, .. }
            | UnknownFormat { file } => Some(file),
            ChannelMap { .. } => None,
        }
    }

    /// The line concerned (1-based, header is line 1), if any.
    pub fn line(&self) -> Option<u64> {
        use DataError::*;
        match self {
            Csv { line, .. } => *line,
            BadCell { line, .. } | TimeNotIncreasing { line, .. } | FieldCount { line, .. } => {
                Some(*line)
            }
            TimeGap { line, .. } => *line,
            DuplicateColumn { .. } | UnknownUnit { .. } | IncompatibleUnit { .. } => Some(1),
            // in a text file: the header lacks the column; the file ends
            // after its last sample
            MissingColumn { file, .. } if is_text(file) => Some(1),
            TooShort { file, samples, .. } if is_text(file) => Some(*samples as u64 + 1),
            _ => None,
        }
    }

    /// The column concerned (1-based), if any.
    pub fn column(&self) -> Option<usize> {
        use DataError::*;
        match self {
            BadCell { column, .. }
            | TimeNotIncreasing { column, .. }
            | UnknownUnit { column, .. }
            | IncompatibleUnit { column, .. } => Some(*column),
            DuplicateColumn { second, .. } => Some(*second),
            FieldCount {
                decimal_comma: Some((c, _)),
                ..
            } => Some(*c),
            _ => None,
        }
    }

    /// The message without location.
    pub fn message(&self) -> String {
        use DataError::*;
        match self {
            Io { message, .. } => format!("cannot read file: {message}"),
            Csv { message, .. } => format!("malformed CSV: {message}"),
            MissingColumn {
                column,
                found,
                expected,
                ..
            } => format!(
                "missing column `{column}`; found columns: {}; expected: {}",
                found.join(", "),
                expected.join(", ")
            ),
            DuplicateColumn {
                column,
                first,
                second,
                ..
            } => format!("column `{column}` appears twice (columns {first} and {second})"),
            BadCell {
                column_name,
                problem,
                ..
            } => match problem {
                CellProblem::Empty => format!("empty cell in column `{column_name}`"),
                CellProblem::NotFinite(s) => {
                    format!("non-finite value `{s}` in column `{column_name}`")
                }
                CellProblem::Unparsable(s) => {
                    format!("cannot parse `{s}` as a number in column `{column_name}`")
                }
                CellProblem::TooLarge(s) => format!(
                    "value `{s}` in column `{column_name}` is beyond {:e} in SI units: its square \
                     overflows (fit % and RMSE would be NaN)",
                    crate::data::MAX_ABS_VALUE
                ),
            },
            TimeNotIncreasing {
                previous, value, ..
            } => {
                if value == previous {
                    format!("duplicate time {value} s (the previous sample has the same time)")
                } else {
                    format!("time goes backwards: {value} s after {previous} s")
                }
            }
            TimeGap {
                sample,
                from,
                to,
                median_dt,
                ..
            } => format!(
                "the time jumps from {from} s to {to} s at sample {sample}: {:.3e} median \
                 sampling intervals ({median_dt} s); a gap this long is not one sampled \
                 experiment (the simulation would hold the input across it)",
                (to - from) / median_dt
            ),
            TooShort {
                samples, minimum, ..
            } => format!("file too short: {samples} samples, at least {minimum} needed"),
            UnknownUnit {
                header, unit, kind, ..
            } => format!("unknown unit suffix `[{unit}]` in header `{header}` ({kind} column)"),
            IncompatibleUnit {
                header,
                unit,
                expected,
                found,
                ..
            } => format!(
                "unit `[{unit}]` in header `{header}` is a {found} unit, but the column is a {expected}"
            ),
            Mat { message, .. } => message.clone(),
            ChannelMap { message } => format!("bad channel mapping: {message}"),
            FieldCount {
                expected,
                found,
                decimal_comma,
                ..
            } => {
                let mut m = format!(
                    "this row has {found} fields, the header has {expected}: its cells would be read from the wrong columns"
                );
                if let Some((_, text)) = decimal_comma {
                    m.push_str(&format!("; `{text}` looks like a number with a decimal comma"));
                }
                m
            }
            UnknownFormat { .. } => "unknown file format (expected .csv or .mat)".to_string(),
        }
    }

    /// A hint on how to fix the problem.
    pub fn help(&self) -> String {
        use crate::units::known_units;
        use DataError::*;
        match self {
            Io { .. } => "check the path and its permissions".into(),
            Csv { .. } => "the file must be comma-separated with one header line".into(),
            MissingColumn { .. } => {
                "name the columns after the model's channels (time in `t`); a unit suffix like `alpha[deg]` is allowed".into()
            }
            DuplicateColumn { .. } => "rename or remove one of the two columns".into(),
            BadCell { .. } => {
                "every needed cell must hold a finite number; cut the file or fill the gap".into()
            }
            TimeNotIncreasing { .. } => {
                "time in column `t` must strictly increase; remove repeated or out-of-order rows".into()
            }
            TimeGap { .. } => {
                "fix the stamp if it is wrong, or split the file at this sample into two experiments".into()
            }
            TooShort { .. } => "record a longer experiment".into(),
            UnknownUnit { kind, .. } | IncompatibleUnit { expected: kind, .. } => {
                let known = known_units(*kind);
                format!("known units for a {kind} column: {}", known.join(", "))
            }
            Mat { help, .. } => help.clone(),
            ChannelMap { .. } => {
                "give the signal rows in order after time, e.g. `--channels theta,alpha,Vm`".into()
            }
            FieldCount {
                decimal_comma: Some(_),
                ..
            } => "write numbers with a decimal point (`3.14`): fields are separated by commas".into(),
            FieldCount { .. } => {
                "every row needs exactly one field per header column; fix or remove this row (a row cut short by a crash can be deleted)".into()
            }
            UnknownFormat { .. } => "give a .csv file with a header or a MAT v5 .mat file".into(),
        }
    }
}

impl fmt::Display for DataError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(file) = self.file() {
            write!(f, "{}", file.display())?;
            if let Some(line) = self.line() {
                write!(f, ":{line}")?;
                if let Some(col) = self.column() {
                    write!(f, ":{col}")?;
                }
            }
            write!(f, ": ")?;
        }
        write!(f, "{}\n  help: {}", self.message(), self.help())
    }
}

impl std::error::Error for DataError {}

/// Something suspicious in a file that does not stop it from loading.
#[derive(Clone, Debug, PartialEq)]
pub enum DataWarning {
    /// An angle column without a unit suffix whose values look like degrees.
    LooksLikeDegrees {
        /// The file.
        file: PathBuf,
        /// The column name.
        column: String,
        /// Which rule of the heuristic fired, with its numbers.
        reason: String,
    },
    /// A length column without a unit suffix whose values look like mm or cm.
    LooksLikeMillimetres {
        /// The file.
        file: PathBuf,
        /// The column name.
        column: String,
        /// Largest absolute value.
        max_abs: f64,
    },
    /// An extra (unused) column was dropped because it is not numeric.
    DroppedColumn {
        /// The file.
        file: PathBuf,
        /// The column header.
        column: String,
        /// First line with a bad cell.
        line: u64,
    },
    /// An extra column carries an unknown unit suffix; its values were kept as written.
    UnknownExtraUnit {
        /// The file.
        file: PathBuf,
        /// The column header.
        column: String,
    },
    /// The sampling interval varies by more than 1 % from its median.
    IrregularSampling {
        /// The file.
        file: PathBuf,
        /// The median interval (s).
        median_dt: f64,
        /// The smallest interval (s).
        min_dt: f64,
        /// The largest interval (s).
        max_dt: f64,
    },
    /// The time column has no unit suffix and steps so slowly that it is
    /// probably in milliseconds (or microseconds).
    LooksLikeMilliseconds {
        /// The file.
        file: PathBuf,
        /// The median step of time as read (s).
        median_dt: f64,
    },
    /// An angle column that jumps by more than half a turn between two
    /// samples: wrapped into a range of one turn by whatever wrote it; read
    /// unwrapped.
    WrappedAngle {
        /// The file.
        file: PathBuf,
        /// The column name.
        column: String,
        /// How many steps were unwrapped.
        jumps: usize,
    },
    /// Something about a MAT file's layout was assumed.
    MatLayout {
        /// The file.
        file: PathBuf,
        /// What was assumed.
        message: String,
    },
}

impl fmt::Display for DataWarning {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DataWarning::LooksLikeDegrees {
                file,
                column,
                reason,
            } => write!(
                f,
                "{}: warning: angle column `{column}` has no unit suffix and looks like degrees ({reason}); it is read as radians: write `{column}[deg]` if it is in degrees",
                file.display()
            ),
            DataWarning::LooksLikeMillimetres {
                file,
                column,
                max_abs,
            } => write!(
                f,
                "{}: warning: length column `{column}` has no unit suffix and reaches {max_abs} (read as metres): write `{column}[mm]` or `{column}[cm]` if it is not in metres",
                file.display()
            ),
            DataWarning::DroppedColumn { file, column, line } => write!(
                f,
                "{}:{line}: warning: extra column `{column}` is not numeric and was dropped",
                file.display()
            ),
            DataWarning::UnknownExtraUnit { file, column } => write!(
                f,
                "{}: warning: extra column `{column}` has an unknown unit suffix; values kept unconverted",
                file.display()
            ),
            DataWarning::IrregularSampling {
                file,
                median_dt,
                min_dt,
                max_dt,
            } => write!(
                f,
                "{}: warning: irregular sampling: interval from {min_dt} s to {max_dt} s (median {median_dt} s)",
                file.display()
            ),
            DataWarning::LooksLikeMilliseconds { file, median_dt } => write!(
                f,
                "{}: warning: time column `t` has no unit suffix and steps by {median_dt} s (a {} Hz sampling rate, implausibly slow for a rig): if it is in milliseconds write `t[ms]` in the header (`t[us]` for microseconds)",
                file.display(),
                crate::plausibility::rate_text(*median_dt)
            ),
            DataWarning::WrappedAngle { file, column, jumps } => write!(
                f,
                "{}: warning: angle column `{column}` jumps by more than half a turn between samples {jumps} time(s), as an angle wrapped into one turn does (a real joint would need more than half a turn per sample); read unwrapped, each jump taken as whole turns",
                file.display()
            ),
            DataWarning::MatLayout { file, message } => {
                write!(f, "{}: warning: {message}", file.display())
            }
        }
    }
}

//! Measured experiments: time plus named channels, read from CSV or MAT v5 files.

use std::path::{Path, PathBuf};

use crate::error::{DataError, DataWarning};
use crate::units::Kind;

/// Fewest samples a file must have.
pub const MIN_SAMPLES: usize = 10;

/// One measured signal, in SI units.
#[derive(Clone, Debug, PartialEq)]
pub struct Channel {
    /// Channel name (header without unit suffix).
    pub name: String,
    /// Where the unit came from: `Some("deg -> rad")` when converted,
    /// `Some("rad")` when the header named the SI unit, `None` without suffix.
    pub unit_note: Option<String>,
    /// Samples, one per time instant.
    pub values: Vec<f64>,
}

/// One experiment: a time vector and channels of the same length.
#[derive(Clone, Debug, PartialEq)]
pub struct Experiment {
    /// Name (the file stem).
    pub name: String,
    /// The file it came from.
    pub file: PathBuf,
    /// Time in s, strictly increasing.
    pub t: Vec<f64>,
    /// Channels: the expected ones in the order of the [`ChannelSpec`]
    /// (coordinates, then inputs), then extra columns in file order.
    pub channels: Vec<Channel>,
}

impl Experiment {
    /// The channel with this name.
    pub fn channel(&self, name: &str) -> Option<&Channel> {
        self.channels.iter().find(|c| c.name == name)
    }

    /// The values of the channel with this name.
    pub fn values(&self, name: &str) -> Option<&[f64]> {
        self.channel(name).map(|c| c.values.as_slice())
    }

    /// The range (largest less smallest finite value) of the channel with
    /// this name; None without that channel or a finite value in it.
    pub fn range(&self, name: &str) -> Option<f64> {
        let (lo, hi) = self
            .values(name)?
            .iter()
            .filter(|v| v.is_finite())
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
                (l.min(v), h.max(v))
            });
        (hi >= lo).then_some(hi - lo)
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t.len()
    }

    /// True when there are no samples (never for a file that was read).
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    /// Median sampling interval in s (None for fewer than two samples).
    pub fn sample_time(&self) -> Option<f64> {
        median_dt(&self.t)
    }

    /// The channel names, in order.
    pub fn channel_names(&self) -> Vec<&str> {
        self.channels.iter().map(|c| c.name.as_str()).collect()
    }

    /// The record with its channels `inputs` taken as samples of a signal
    /// that varies continuously between them (a simulator integrating a
    /// continuous input, a sensor sampling one), for a simulation that
    /// holds each input value over its sample interval: each sample becomes
    /// the mean over its interval of the line through it and the next,
    /// `(u_k + u_{k+1}) / 2` (the last is kept). Held as recorded, such an
    /// input acts half a sample late.
    pub fn with_continuous_inputs(&self, inputs: &[String]) -> Experiment {
        let mut e = self.clone();
        for c in e.channels.iter_mut().filter(|c| inputs.contains(&c.name)) {
            let v = &c.values;
            c.values = (0..v.len())
                .map(|k| match v.get(k + 1) {
                    Some(next) => 0.5 * (v[k] + next),
                    None => v[k],
                })
                .collect();
        }
        e
    }
}

/// The channels a model needs from a file: coordinates (angles or lengths) and
/// inputs, each with its kind. Only names and kinds: no dependency on the model.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ChannelSpec {
    /// Measured coordinates, e.g. `("theta", Kind::Angle)`.
    pub coordinates: Vec<(String, Kind)>,
    /// Inputs, e.g. `("Vm", Kind::Voltage)`.
    pub inputs: Vec<(String, Kind)>,
    /// Channels read (with their units checked) when the file has them,
    /// not required: e.g. an input that a recorded controller in the loop
    /// can compute.
    pub optional: Vec<(String, Kind)>,
}

impl ChannelSpec {
    /// An empty spec.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds an angle coordinate.
    pub fn angle(mut self, name: &str) -> Self {
        self.coordinates.push((name.to_string(), Kind::Angle));
        self
    }

    /// Adds a length coordinate.
    pub fn length(mut self, name: &str) -> Self {
        self.coordinates.push((name.to_string(), Kind::Length));
        self
    }

    /// Adds an input of the given kind (e.g. [`Kind::Voltage`]).
    pub fn input(mut self, name: &str, kind: Kind) -> Self {
        self.inputs.push((name.to_string(), kind));
        self
    }

    /// Adds a channel read when present (see [`ChannelSpec::optional`]).
    pub fn optional(mut self, name: &str, kind: Kind) -> Self {
        self.optional.push((name.to_string(), kind));
        self
    }

    /// All expected channels, coordinates first.
    pub fn all(&self) -> impl Iterator<Item = &(String, Kind)> {
        self.coordinates.iter().chain(self.inputs.iter())
    }

    /// The kind of a channel, if the spec names it (required or optional).
    pub fn kind_of(&self, name: &str) -> Option<Kind> {
        self.all()
            .chain(self.optional.iter())
            .find(|(n, _)| n == name)
            .map(|(_, k)| *k)
    }

    /// The spec with channels renamed: `(name, column)` reads channel
    /// `name` from the file's column `column`.
    fn renamed(&self, rename: &[(String, String)]) -> ChannelSpec {
        let map = |v: &[(String, Kind)]| -> Vec<(String, Kind)> {
            v.iter()
                .map(|(n, k)| {
                    let col = rename.iter().find(|r| &r.0 == n).map_or(n, |r| &r.1);
                    (col.clone(), *k)
                })
                .collect()
        };
        ChannelSpec {
            coordinates: map(&self.coordinates),
            inputs: map(&self.inputs),
            optional: map(&self.optional),
        }
    }

    /// Expected names with time first, for messages.
    pub(crate) fn expected_names(&self) -> Vec<String> {
        std::iter::once("t".to_string())
            .chain(self.all().map(|(n, _)| n.clone()))
            .collect()
    }
}

/// Options for reading files.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ReadOptions {
    /// For MAT files: names of the signal rows after the time row
    /// (`--channels theta,alpha,Vm`). Without it, the spec's order
    /// (coordinates, then inputs) is assumed and a warning says so.
    pub mat_channels: Option<Vec<String>>,
    /// Channels read from columns of other names: `(name, column)`, e.g.
    /// `("Vm", "plant_input")` (`--map Vm=plant_input`).
    pub rename: Vec<(String, String)>,
}

/// Parses `--map` arguments `NAME=COLUMN[,NAME=COLUMN...]`.
pub fn parse_rename(args: &[String]) -> Result<Vec<(String, String)>, DataError> {
    let mut out: Vec<(String, String)> = Vec::new();
    for a in args {
        for part in a.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let Some((n, c)) = part.split_once('=') else {
                return Err(DataError::ChannelMap {
                    message: format!("`{part}`: expected NAME=COLUMN, e.g. `Vm=plant_input`"),
                });
            };
            let (n, c) = (n.trim(), c.trim());
            if n.is_empty() || c.is_empty() {
                return Err(DataError::ChannelMap {
                    message: format!("`{part}`: expected NAME=COLUMN, e.g. `Vm=plant_input`"),
                });
            }
            if out.iter().any(|(m, _)| m == n) {
                return Err(DataError::ChannelMap {
                    message: format!("`{n}` mapped twice"),
                });
            }
            out.push((n.to_string(), c.to_string()));
        }
    }
    Ok(out)
}

/// Parses a channel mapping argument like `theta,alpha,Vm` (names may carry a
/// unit suffix: `alpha[deg]`).
pub fn parse_channel_map(arg: &str) -> Result<Vec<String>, DataError> {
    let names: Vec<String> = arg.split(',').map(|s| s.trim().to_string()).collect();
    if names.iter().any(|n| n.is_empty()) {
        return Err(DataError::ChannelMap {
            message: format!("empty name in `{arg}`"),
        });
    }
    for (i, n) in names.iter().enumerate() {
        if names[..i].contains(n) {
            return Err(DataError::ChannelMap {
                message: format!("`{n}` given twice in `{arg}`"),
            });
        }
    }
    Ok(names)
}

/// Reads one experiment (CSV by default, MAT v5 for `.mat`) and checks it
/// against the channels the model expects. Returns the experiment and any
/// warnings; never panics on bad input.
pub fn read_experiment(
    path: &Path,
    expected: &ChannelSpec,
) -> Result<(Experiment, Vec<DataWarning>), DataError> {
    read_experiment_with(path, expected, &ReadOptions::default())
}

/// [`read_experiment`] with options (channel mapping for MAT files).
pub fn read_experiment_with(
    path: &Path,
    expected: &ChannelSpec,
    options: &ReadOptions,
) -> Result<(Experiment, Vec<DataWarning>), DataError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase());
    let renamed;
    let expected = if options.rename.is_empty() {
        expected
    } else {
        renamed = expected.renamed(&options.rename);
        &renamed
    };
    check_regular(path, None)?;
    let (mut exp, mut warnings) = match ext.as_deref() {
        Some("mat") => crate::mat_reader::read_mat(path, expected, options)?,
        Some("csv") | Some("txt") | None => crate::csv_reader::read_csv(path, expected)?,
        Some(_) => {
            // Sniff: a MAT v5 file starts with a 116-byte text header "MATLAB 5.0"
            // (only the first bytes are read: the file may be large).
            let head = std::fs::File::open(path).and_then(|f| {
                use std::io::Read;
                let mut head = Vec::with_capacity(6);
                f.take(6).read_to_end(&mut head)?;
                Ok(head)
            });
            match head {
                Ok(bytes) if bytes.starts_with(b"MATLAB") => {
                    crate::mat_reader::read_mat(path, expected, options)?
                }
                Ok(_) => crate::csv_reader::read_csv(path, expected)?,
                Err(e) => {
                    return Err(DataError::Io {
                        file: path.to_path_buf(),
                        message: e.to_string(),
                    })
                }
            }
        }
    };
    let checks = crate::plausibility::check(&exp, expected);
    let degrees: Vec<String> = checks
        .iter()
        .filter_map(|w| match w {
            DataWarning::LooksLikeDegrees { column, .. } => Some(column.clone()),
            _ => None,
        })
        .collect();
    warnings.extend(checks);
    for (name, col) in &options.rename {
        if let Some(c) = exp.channels.iter_mut().find(|c| &c.name == col) {
            c.name = name.clone();
        }
    }
    // angles wrapped into one turn (not those that look like degrees: their
    // turn is 360, and the user is told to say so)
    for (name, kind) in &expected.coordinates {
        if *kind != Kind::Angle || degrees.contains(name) {
            continue;
        }
        if let Some(c) = exp.channels.iter_mut().find(|c| &c.name == name) {
            let jumps = unwrap_angle(&mut c.values);
            if jumps > 0 {
                warnings.push(DataWarning::WrappedAngle {
                    file: exp.file.clone(),
                    column: name.clone(),
                    jumps,
                });
            }
        }
    }
    Ok((exp, warnings))
}

/// Unwrap an angle series in place: a step of more than half a turn (pi)
/// between two samples is taken as the wrap of an angle kept within one
/// turn, and whole turns are added from there on so that the step is the
/// one below half a turn. A joint would need to turn more than half a turn
/// per sample to make such a step (1,570 rad/s at 500 Hz): aliased at any
/// real speed. Returns the number of steps unwrapped.
pub fn unwrap_angle(values: &mut [f64]) -> usize {
    use std::f64::consts::PI;
    let mut shift = 0.0;
    let mut jumps = 0;
    let mut prev = match values.first() {
        Some(v) => *v,
        None => return 0,
    };
    for v in values.iter_mut().skip(1) {
        let raw = *v;
        let step = raw - prev;
        if step.abs() > PI && step.is_finite() {
            shift -= 2.0 * PI * (step / (2.0 * PI)).round();
            jumps += 1;
        }
        prev = raw;
        *v = raw + shift;
    }
    jumps
}

/// Reads several files: one experiment each. Stops at the first error.
/// Experiment names are unique (see [`unique_names`]): tables and figure
/// files never merge two experiments.
pub fn read_experiments<P: AsRef<Path>>(
    paths: &[P],
    expected: &ChannelSpec,
    options: &ReadOptions,
) -> Result<(Vec<Experiment>, Vec<DataWarning>), DataError> {
    let mut exps = Vec::with_capacity(paths.len());
    let mut warnings = Vec::new();
    for p in paths {
        let (e, w) = read_experiment_with(p.as_ref(), expected, options)?;
        exps.push(e);
        warnings.extend(w);
    }
    unique_names(&mut exps);
    Ok((exps, warnings))
}

/// Makes experiment names unique: files with the same stem from different
/// folders are named `<folder>-<stem>` (`a/exp.csv`, `b/exp.csv` -> `a-exp`,
/// `b-exp`); any name still repeated gets `-2`, `-3`, ... Unique names are
/// left alone.
pub fn unique_names(exps: &mut [Experiment]) {
    let count = |exps: &[Experiment], name: &str| exps.iter().filter(|e| e.name == name).count();
    let repeated: Vec<bool> = exps.iter().map(|e| count(exps, &e.name) > 1).collect();
    for (e, rep) in exps.iter_mut().zip(repeated) {
        if rep {
            if let Some(folder) = e.file.canonicalize().ok().and_then(|p| {
                p.parent()
                    .and_then(|d| d.file_name())
                    .map(|s| s.to_string_lossy().into_owned())
            }) {
                e.name = format!("{folder}-{}", e.name);
            }
        }
    }
    for i in 0..exps.len() {
        let mut k = 1;
        let base = exps[i].name.clone();
        while exps[..i].iter().any(|e| e.name == exps[i].name) {
            k += 1;
            exps[i].name = format!("{base}-{k}");
        }
    }
}

/// The experiment name for a file: its stem.
pub(crate) fn experiment_name(path: &Path) -> String {
    path.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| path.display().to_string())
}

/// Largest magnitude of a value read (SI units): 1e150. Fit %, RMSE and the
/// fit's cost sum squares of values and residuals; with |v| up to 1e150 a
/// sum over 1e7 samples stays below f64's 1.8e308 (1e300 in one cell made
/// fit % NaN with exit 0). No measurement of a rig comes near.
pub const MAX_ABS_VALUE: f64 = 1e150;

/// Longest sampling interval accepted, in median intervals: 1000. Dropped
/// samples make intervals of a few periods; at the 100 Hz-10 kHz rates of
/// the rigs, 1000 periods are 0.1-10 s without a measurement while the
/// simulation holds the input, which is no longer one sampled experiment but
/// two (or one wrong stamp: `1e6` at the end of a 20 s record made `compare`
/// simulate for minutes).
pub const MAX_GAP_INTERVALS: f64 = 1000.0;

/// The first sampling interval longer than [`MAX_GAP_INTERVALS`] median
/// intervals: (index of the sample after it, median interval).
pub(crate) fn first_gap(t: &[f64]) -> Option<(usize, f64)> {
    let med = median_dt(t)?;
    t.windows(2)
        .position(|w| w[1] - w[0] > MAX_GAP_INTERVALS * med)
        .map(|i| (i + 1, med))
}

/// Refuses a path that is not a regular file (a FIFO would block the open,
/// a device like `/dev/zero` never end) or, when `max` is given, one larger
/// than `max` bytes.
pub(crate) fn check_regular(path: &Path, max: Option<u64>) -> Result<(), DataError> {
    let io = |message: String| DataError::Io {
        file: path.to_path_buf(),
        message,
    };
    let m = std::fs::metadata(path).map_err(|e| io(e.to_string()))?;
    if !m.is_file() {
        return Err(io(if m.is_dir() {
            "a directory, not a recording".into()
        } else {
            "not a regular file (a FIFO, socket or device): recordings are read from files".into()
        }));
    }
    if let Some(max) = max.filter(|&max| m.len() > max) {
        return Err(io(format!(
            "the file has {} bytes; the reader's limit is {} MiB",
            m.len(),
            max >> 20
        )));
    }
    Ok(())
}

/// The bytes of a regular file of at most `max` bytes.
pub(crate) fn read_regular(path: &Path, max: u64) -> Result<Vec<u8>, DataError> {
    check_regular(path, Some(max))?;
    std::fs::read(path).map_err(|e| DataError::Io {
        file: path.to_path_buf(),
        message: e.to_string(),
    })
}

/// Index of the first sample whose time does not exceed the previous one.
pub(crate) fn first_non_increasing(t: &[f64]) -> Option<usize> {
    t.windows(2).position(|w| w[1] <= w[0]).map(|i| i + 1)
}

/// Median of the positive sampling intervals.
pub(crate) fn median_dt(t: &[f64]) -> Option<f64> {
    if t.len() < 2 {
        return None;
    }
    let mut d: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    // (the middle element of the sorted order, without sorting)
    let mid = d.len() / 2;
    Some(*d.select_nth_unstable_by(mid, f64::total_cmp).1)
}

/// A warning if the sampling interval varies by more than 1 %.
pub(crate) fn sampling_warning(file: &Path, t: &[f64]) -> Option<DataWarning> {
    let med = median_dt(t)?;
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for w in t.windows(2) {
        let d = w[1] - w[0];
        lo = lo.min(d);
        hi = hi.max(d);
    }
    if (hi - med) > 0.01 * med || (med - lo) > 0.01 * med {
        Some(DataWarning::IrregularSampling {
            file: file.to_path_buf(),
            median_dt: med,
            min_dt: lo,
            max_dt: hi,
        })
    } else {
        None
    }
}

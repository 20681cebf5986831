//! MAT v5 files as written by Simulink/QUARC "To File" blocks: one numeric
//! matrix whose first row is time and whose other rows are signals. Row names
//! come from a mapping (`--channels theta,alpha,Vm`), since the file has none.
//!
//! Parsing uses the `matfile` crate (uncompressed and zlib-compressed data
//! elements). It is called behind `catch_unwind` so that a malformed file gives
//! an error, never a panic.

use std::path::Path;

use crate::csv_reader::unit_factor;
use crate::data::{
    experiment_name, first_non_increasing, sampling_warning, Channel, ChannelSpec, Experiment,
    ReadOptions, MIN_SAMPLES,
};
use crate::error::{DataError, DataWarning};
use crate::units::{split_header, Kind};

/// Reads a MAT experiment. See [`crate::read_experiment_with`].
pub(crate) fn read_mat(
    path: &Path,
    spec: &ChannelSpec,
    options: &ReadOptions,
) -> Result<(Experiment, Vec<DataWarning>), DataError> {
    let file = path.to_path_buf();
    let mat_err = |message: String, help: &str| DataError::Mat {
        file: file.clone(),
        message,
        help: help.to_string(),
    };
    let bytes = std::fs::read(path).map_err(|e| DataError::Io {
        file: file.clone(),
        message: e.to_string(),
    })?;
    let parsed = std::panic::catch_unwind(|| matfile::MatFile::parse(bytes.as_slice()));
    let mat = match parsed {
        Ok(Ok(m)) => m,
        Ok(Err(e)) => {
            return Err(mat_err(
                format!("not a readable MAT v5 file: {e}"),
                "save with `save -v7 file.mat` (v7.3/HDF5 files are not supported)",
            ))
        }
        Err(_) => {
            return Err(mat_err(
                "malformed MAT v5 file (the parser gave up)".into(),
                "save with `save -v7 file.mat` (v7.3/HDF5 files are not supported)",
            ))
        }
    };
    let mut warnings = Vec::new();

    // Row names after time.
    let names: Vec<String> = match &options.mat_channels {
        Some(m) => m.clone(),
        None => {
            let names: Vec<String> = spec.all().map(|(n, _)| n.clone()).collect();
            warnings.push(DataWarning::MatLayout {
                file: file.clone(),
                message: format!(
                    "no channel mapping given: signal rows assumed to be {} in that order",
                    names.join(",")
                ),
            });
            names
        }
    };
    let rows = names.len() + 1;

    // Find the matrix: (k+1) x N preferred, N x (k+1) accepted.
    let arrays = mat.arrays();
    let listing = arrays
        .iter()
        .map(|a| format!("{} {:?}", a.name(), a.size()))
        .collect::<Vec<_>>()
        .join(", ");
    let pick = arrays
        .iter()
        .find(|a| a.ndims() == 2 && a.size()[0] == rows)
        .map(|a| (a, false))
        .or_else(|| {
            arrays
                .iter()
                .find(|a| a.ndims() == 2 && a.size()[1] == rows && a.size()[0] != rows)
                .map(|a| (a, true))
        });
    let Some((array, transposed)) = pick else {
        return Err(mat_err(
            format!(
                "no numeric matrix with {rows} rows (time + {}) found in the MAT file; arrays: [{listing}]",
                names.join(",")
            ),
            "give one name per signal row after time with `--channels theta,alpha,Vm`",
        ));
    };
    let candidates = arrays
        .iter()
        .filter(|a| a.ndims() == 2 && (a.size()[0] == rows || a.size()[1] == rows))
        .count();
    if candidates > 1 {
        warnings.push(DataWarning::MatLayout {
            file: file.clone(),
            message: format!("several matrices fit; using `{}`", array.name()),
        });
    }
    if transposed {
        warnings.push(DataWarning::MatLayout {
            file: file.clone(),
            message: format!(
                "matrix `{}` has signals in columns, not rows; read transposed",
                array.name()
            ),
        });
    }
    let data = to_f64(array.data()).ok_or_else(|| {
        mat_err(
            format!("matrix `{}` is complex", array.name()),
            "store real signals",
        )
    })?;
    let (r, c) = (array.size()[0], array.size()[1]);
    let n = if transposed { r } else { c };
    // Element (i, j) of a column-major r x c matrix is data[i + j r].
    let row = |k: usize| -> Vec<f64> {
        (0..n)
            .map(|j| {
                let idx = if transposed { j + k * r } else { k + j * r };
                data.get(idx).copied().unwrap_or(f64::NAN)
            })
            .collect()
    };

    if n < MIN_SAMPLES {
        return Err(DataError::TooShort {
            file,
            samples: n,
            minimum: MIN_SAMPLES,
        });
    }
    let t = row(0);
    for (k, name) in std::iter::once("t")
        .chain(names.iter().map(String::as_str))
        .enumerate()
    {
        let vals = if k == 0 { t.clone() } else { row(k) };
        if let Some(j) = vals.iter().position(|v| !v.is_finite()) {
            return Err(mat_err(
                format!(
                    "non-finite value {} in row {} (`{name}`) at sample {}",
                    vals[j],
                    k + 1,
                    j + 1
                ),
                "every sample must be a finite number",
            ));
        }
    }
    if let Some(j) = first_non_increasing(&t) {
        return Err(mat_err(
            format!(
                "time (row 1) does not increase at sample {}: {} s after {} s",
                j + 1,
                t[j],
                t[j - 1]
            ),
            "the first row must be strictly increasing time in s",
        ));
    }

    // Build channels: spec order first, then extras in mapping order.
    let split: Vec<(String, Option<String>)> = names
        .iter()
        .map(|h| {
            let (n, u) = split_header(h);
            (n.to_string(), u.map(str::to_string))
        })
        .collect();
    let found: Vec<String> = split.iter().map(|(n, _)| n.clone()).collect();
    let mut order: Vec<(usize, Kind)> = Vec::new();
    for (name, kind) in spec.all() {
        let Some(k) = found.iter().position(|n| n == name) else {
            return Err(DataError::MissingColumn {
                file,
                column: name.clone(),
                found,
                expected: spec.expected_names(),
            });
        };
        order.push((k, *kind));
    }
    for k in 0..found.len() {
        if !order.iter().any(|(i, _)| *i == k) {
            order.push((k, Kind::Other));
        }
    }
    let mut channels = Vec::new();
    for (k, kind) in order {
        let (name, unit) = &split[k];
        let (factor, note) = unit_factor(&file, k + 2, &names[k], unit.as_deref(), kind)?;
        channels.push(Channel {
            name: name.clone(),
            unit_note: note,
            values: row(k + 1).into_iter().map(|v| v * factor).collect(),
        });
    }
    warnings.extend(sampling_warning(&file, &t));
    warnings.extend(crate::plausibility::time_unit_warning(&file, &t));
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

/// Any real numeric class as f64; None for complex data.
fn to_f64(data: &matfile::NumericData) -> Option<Vec<f64>> {
    use matfile::NumericData as D;
    fn conv<T: Copy + Into<f64>>(real: &[T], imag: &Option<Vec<T>>) -> Option<Vec<f64>> {
        if imag.is_some() {
            return None;
        }
        Some(real.iter().map(|&v| v.into()).collect())
    }
    match data {
        D::Double { real, imag } => conv(real, imag),
        D::Single { real, imag } => conv(real, imag),
        D::Int8 { real, imag } => conv(real, imag),
        D::UInt8 { real, imag } => conv(real, imag),
        D::Int16 { real, imag } => conv(real, imag),
        D::UInt16 { real, imag } => conv(real, imag),
        D::Int32 { real, imag } => conv(real, imag),
        D::UInt32 { real, imag } => conv(real, imag),
        D::Int64 { real, imag } => {
            if imag.is_some() {
                None
            } else {
                Some(real.iter().map(|&v| v as f64).collect())
            }
        }
        D::UInt64 { real, imag } => {
            if imag.is_some() {
                None
            } else {
                Some(real.iter().map(|&v| v as f64).collect())
            }
        }
    }
}

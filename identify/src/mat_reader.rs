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

/// Most bytes of MAT data read, compressed elements inflated: 256 MiB,
/// 3.3e7 doubles (time and three signals over 8e6 samples: 2.2 h at 1 kHz).
/// The reader holds the data about three times (the file, the parsed
/// matrix, the channels), so a file at the limit stays under 1 GB; beyond,
/// a zlib stream that inflates 1000-fold (a 4 MB file declaring 4 GB) is
/// refused while it is inflated, before anything of its size is allocated.
pub const MAX_MAT_BYTES: u64 = 256 << 20;

/// MAT v5 element types the reader keeps at the top level.
const MI_MATRIX: u32 = 14;
const MI_COMPRESSED: u32 = 15;

/// The file with every top-level compressed element inflated in place
/// (under [`MAX_MAT_BYTES`] in all) and the top-level elements that are not
/// matrices dropped, so the MAT parser sees only uncompressed matrices and
/// never inflates or allocates on its own. A file whose header or element
/// tags do not add up is passed on as it is, for the parser's error.
fn inflate_elements(bytes: Vec<u8>) -> Result<Vec<u8>, String> {
    inflate_elements_within(bytes, MAX_MAT_BYTES)
}

/// [`inflate_elements`] with a budget of `max` inflated bytes.
fn inflate_elements_within(bytes: Vec<u8>, max: u64) -> Result<Vec<u8>, String> {
    use std::io::Read;
    if bytes.len() < 128 {
        return Ok(bytes);
    }
    let little = match &bytes[126..128] {
        b"IM" => true,
        b"MI" => false,
        _ => return Ok(bytes),
    };
    let word = |at: usize| {
        let b = [bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]];
        if little {
            u32::from_le_bytes(b)
        } else {
            u32::from_be_bytes(b)
        }
    };
    let mut out = bytes[..128].to_vec();
    let mut budget = max;
    let mut pos = 128;
    while pos + 8 <= bytes.len() {
        let (ty, size) = (word(pos), word(pos + 4) as usize);
        let Some(end) = (pos + 8).checked_add(size).filter(|&e| e <= bytes.len()) else {
            out.extend_from_slice(&bytes[pos..]);
            break;
        };
        if ty & 0xFFFF_0000 != 0 {
            // a small element at the top level: not a variable
            out.extend_from_slice(&bytes[pos..]);
            break;
        }
        let padded = end.div_ceil(8) * 8;
        match ty {
            MI_COMPRESSED => {
                let mut inflated = Vec::new();
                let decoder = libflate::zlib::Decoder::new(&bytes[pos + 8..end])
                    .map_err(|e| format!("a compressed element does not inflate: {e}"))?;
                decoder
                    .take(budget + 1)
                    .read_to_end(&mut inflated)
                    .map_err(|e| format!("a compressed element does not inflate: {e}"))?;
                if inflated.len() as u64 > budget {
                    return Err(format!(
                        "the compressed data inflate beyond the reader's limit of {} MiB (from \
                         a {} KB element): a recording this large (or a zip bomb) is refused",
                        max >> 20,
                        size / 1000
                    ));
                }
                budget -= inflated.len() as u64;
                out.extend_from_slice(&inflated);
                out.resize(out.len().div_ceil(8) * 8, 0);
                pos = end; // compressed elements are not padded
            }
            MI_MATRIX => {
                out.extend_from_slice(&bytes[pos..padded.min(bytes.len())]);
                out.resize(out.len().div_ceil(8) * 8, 0);
                pos = padded;
            }
            _ => pos = padded,
        }
    }
    Ok(out)
}

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
    let bytes = crate::data::read_regular(path, MAX_MAT_BYTES)?;
    let bytes = inflate_elements(bytes).map_err(|m| {
        mat_err(
            m,
            "a recording of this size is not supported: save a shorter one (or fewer signals)",
        )
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
        if let Some(j) = vals
            .iter()
            .position(|v| !v.is_finite() || v.abs() > crate::data::MAX_ABS_VALUE)
        {
            return Err(mat_err(
                format!(
                    "value {} in row {} (`{name}`) at sample {} is not a finite number within 1e150",
                    vals[j],
                    k + 1,
                    j + 1
                ),
                "every sample must be a finite number of magnitude at most 1e150",
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

    if let Some((sample, median_dt)) = crate::data::first_gap(&t) {
        return Err(DataError::TimeGap {
            file,
            line: None,
            sample: sample + 1,
            from: t[sample - 1],
            to: t[sample],
            median_dt,
        });
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

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    fn element(ty: u32, payload: &[u8]) -> Vec<u8> {
        let mut e = ty.to_le_bytes().to_vec();
        e.extend((payload.len() as u32).to_le_bytes());
        e.extend(payload);
        e.resize(e.len().div_ceil(8) * 8, 0);
        e
    }

    /// A MAT v5 file (little endian) holding one 2 x `n` double matrix
    /// `data`, its element zlib-compressed when `compress`.
    fn mat_file(n: usize, compress: bool) -> Vec<u8> {
        let mut m = element(6, &[6, 0, 0, 0, 0, 0, 0, 0]); // flags: double
        m.extend(element(5, &[2, 0, 0, 0, n as u8, 0, 0, 0])); // dims 2 x n
        m.extend(element(1, b"data"));
        let values: Vec<u8> = (0..2 * n).flat_map(|k| (k as f64).to_le_bytes()).collect();
        m.extend(element(9, &values));
        let matrix = element(MI_MATRIX, &m);
        let mut file = b"MATLAB 5.0 MAT-file".to_vec();
        file.resize(116, b' ');
        file.extend([0u8; 8]);
        file.extend(0x0100u16.to_le_bytes());
        file.extend(b"IM");
        if compress {
            let mut enc = libflate::zlib::Encoder::new(Vec::new()).unwrap();
            enc.write_all(&matrix).unwrap();
            let z = enc.finish().into_result().unwrap();
            file.extend(MI_COMPRESSED.to_le_bytes());
            file.extend((z.len() as u32).to_le_bytes());
            file.extend(z);
        } else {
            file.extend(matrix);
        }
        file
    }

    #[test]
    fn compressed_elements_inflate_to_the_uncompressed_file() {
        let plain = mat_file(20, false);
        let inflated = inflate_elements_within(mat_file(20, true), 1 << 20).unwrap();
        assert_eq!(inflated, plain);
        let m = matfile::MatFile::parse(inflated.as_slice()).unwrap();
        assert_eq!(m.arrays()[0].size(), &[2, 20]);
    }

    /// Issue 31 (r08): a stream that inflates beyond the budget is refused
    /// while it inflates (here 2 x 200 doubles = 3.2 KB against 1 KB).
    #[test]
    fn a_zip_bomb_is_refused_within_the_budget() {
        let e = inflate_elements_within(mat_file(200, true), 1024).unwrap_err();
        assert!(
            e.contains("limit of 0 MiB") || e.contains("inflate beyond"),
            "{e}"
        );
        // the budget counts every element of the file
        let mut two = mat_file(20, true);
        let one = two[128..].to_vec();
        two.extend(one);
        let single = inflate_elements_within(mat_file(20, true), 1 << 20)
            .unwrap()
            .len()
            - 128;
        assert!(inflate_elements_within(two.clone(), single as u64 + 100).is_err());
        assert!(inflate_elements_within(two, 2 * single as u64).is_ok());
    }
}

//! MAT v5 reading on files written here byte by byte (QUARC "To File" layout:
//! one matrix, first row time, other rows signals).

mod common;

use std::io::Write;

use common::*;
use plantc_identify::{parse_channel_map, read_experiment, read_experiment_with, ReadOptions};

const MI_INT8: u32 = 1;
const MI_INT32: u32 = 5;
const MI_UINT32: u32 = 6;
const MI_DOUBLE: u32 = 9;
const MI_MATRIX: u32 = 14;
const MI_COMPRESSED: u32 = 15;
const MX_DOUBLE_CLASS: u32 = 6;

/// One data element: tag, data, padding to 8 bytes.
fn element(ty: u32, data: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    out.extend(ty.to_le_bytes());
    out.extend((data.len() as u32).to_le_bytes());
    out.extend(data);
    while out.len() % 8 != 0 {
        out.push(0);
    }
    out
}

/// A miMATRIX element holding a real double matrix (column-major `data`).
fn matrix(name: &str, rows: usize, cols: usize, data: &[f64]) -> Vec<u8> {
    let mut body = Vec::new();
    let flags: Vec<u8> = [MX_DOUBLE_CLASS, 0]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    body.extend(element(MI_UINT32, &flags));
    let dims: Vec<u8> = [rows as i32, cols as i32]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    body.extend(element(MI_INT32, &dims));
    body.extend(element(MI_INT8, name.as_bytes()));
    let real: Vec<u8> = data.iter().flat_map(|v| v.to_le_bytes()).collect();
    body.extend(element(MI_DOUBLE, &real));
    element(MI_MATRIX, &body)
}

/// A MAT v5 file: 128-byte header, then elements (zlib-compressed if asked).
fn mat_file(elements: &[Vec<u8>], compressed: bool) -> Vec<u8> {
    let mut out = Vec::new();
    let mut text = b"MATLAB 5.0 MAT-file, Platform: GLNXA64, Created by: plantc tests".to_vec();
    text.resize(116, b' ');
    out.extend(text);
    out.extend([0u8; 8]); // subsystem data offset
    out.extend(0x0100u16.to_le_bytes()); // version
    out.extend(b"IM"); // little-endian marker
    for e in elements {
        if compressed {
            let mut enc = libflate::zlib::Encoder::new(Vec::new()).unwrap();
            enc.write_all(e).unwrap();
            let z = enc.finish().into_result().unwrap();
            out.extend(MI_COMPRESSED.to_le_bytes());
            out.extend((z.len() as u32).to_le_bytes());
            out.extend(z);
        } else {
            out.extend(e);
        }
    }
    out
}

/// Rows t, theta, alpha, Vm over `n` samples, column-major (4 x n).
fn quarc_data(n: usize) -> Vec<f64> {
    (0..n)
        .flat_map(|k| {
            let t = k as f64 * 0.002;
            [
                t,
                0.01 * k as f64,
                std::f64::consts::PI - 0.001 * k as f64,
                1.5,
            ]
        })
        .collect()
}

fn write_bytes(test: &str, name: &str, bytes: &[u8]) -> std::path::PathBuf {
    let p = scratch(test).join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

fn opts(map: &str) -> ReadOptions {
    ReadOptions {
        mat_channels: Some(parse_channel_map(map).unwrap()),
        ..Default::default()
    }
}

#[test]
fn reads_uncompressed_and_compressed() {
    for compressed in [false, true] {
        let bytes = mat_file(&[matrix("data", 4, 50, &quarc_data(50))], compressed);
        let p = write_bytes(&format!("mat{compressed}"), "run.mat", &bytes);
        let (e, w) = read_experiment_with(&p, &pendulum_spec(), &opts("theta,alpha,Vm")).unwrap();
        assert!(w.is_empty(), "{w:?}");
        assert_eq!(e.len(), 50);
        assert_eq!(e.name, "run");
        assert!((e.t[10] - 0.02).abs() < 1e-15);
        assert!((e.values("theta").unwrap()[10] - 0.1).abs() < 1e-15);
        assert_eq!(e.values("Vm").unwrap()[3], 1.5);
    }
}

#[test]
fn mapping_order_and_units() {
    // Rows stored as alpha (deg), Vm, theta; mapped by name.
    let n = 20;
    let data: Vec<f64> = (0..n)
        .flat_map(|k| [k as f64 * 0.002, 180.0, 2.0, 0.25])
        .collect();
    let p = write_bytes(
        "matmap",
        "m.mat",
        &mat_file(&[matrix("x", 4, n, &data)], true),
    );
    let (e, _) =
        read_experiment_with(&p, &pendulum_spec(), &opts("alpha[deg], Vm, theta")).unwrap();
    assert_eq!(e.channel_names(), vec!["theta", "alpha", "Vm"]);
    assert!((e.values("alpha").unwrap()[0] - std::f64::consts::PI).abs() < 1e-12);
    assert_eq!(e.values("theta").unwrap()[0], 0.25);
}

#[test]
fn without_mapping_spec_order_is_assumed_with_warning() {
    let p = write_bytes(
        "matnomap",
        "m.mat",
        &mat_file(&[matrix("d", 4, 30, &quarc_data(30))], false),
    );
    let (e, w) = read_experiment(&p, &pendulum_spec()).unwrap();
    assert_eq!(e.len(), 30);
    assert!(w[0].to_string().contains("no channel mapping"), "{}", w[0]);
}

#[test]
fn transposed_matrix_is_accepted_with_warning() {
    // 30 x 4, signals in columns: column-major data is row after row of the 4 x 30.
    let src = quarc_data(30); // (4 x 30) column-major = each sample's 4 values
    let mut data = vec![0.0; 120];
    for k in 0..30 {
        for r in 0..4 {
            data[k + r * 30] = src[r + 4 * k];
        }
    }
    let p = write_bytes(
        "mattr",
        "m.mat",
        &mat_file(&[matrix("d", 30, 4, &data)], false),
    );
    let (e, w) = read_experiment_with(&p, &pendulum_spec(), &opts("theta,alpha,Vm")).unwrap();
    assert!((e.values("theta").unwrap()[7] - 0.07).abs() < 1e-15);
    assert!(w.iter().any(|w| w.to_string().contains("transposed")));
}

#[test]
fn bad_mat_files_are_errors_not_panics() {
    let spec = pendulum_spec();
    // Garbage after a valid header.
    let mut bytes = mat_file(&[], false);
    bytes.extend([14, 0, 0, 0, 200, 0, 0, 0, 1, 2, 3]);
    let p = write_bytes("matbad1", "g.mat", &bytes);
    let msg = read_experiment_with(&p, &spec, &opts("theta,alpha,Vm"))
        .unwrap_err()
        .to_string();
    assert!(msg.contains("g.mat") && msg.contains("MAT"), "{msg}");

    // Wrong number of rows for the mapping.
    let p = write_bytes(
        "matbad2",
        "r.mat",
        &mat_file(&[matrix("d", 4, 30, &quarc_data(30))], false),
    );
    let msg = read_experiment_with(&p, &spec, &opts("theta,alpha"))
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("no numeric matrix with 3 rows") && msg.contains("d [4, 30]"),
        "{msg}"
    );

    // Time not increasing.
    let mut d = quarc_data(30);
    d[4 * 5] = d[4 * 4];
    let p = write_bytes(
        "matbad3",
        "t.mat",
        &mat_file(&[matrix("d", 4, 30, &d)], true),
    );
    let msg = read_experiment_with(&p, &spec, &opts("theta,alpha,Vm"))
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("t.mat") && msg.contains("does not increase at sample 6"),
        "{msg}"
    );

    // NaN.
    let mut d = quarc_data(30);
    d[4 * 7 + 2] = f64::NAN;
    let p = write_bytes(
        "matbad4",
        "n.mat",
        &mat_file(&[matrix("d", 4, 30, &d)], false),
    );
    let msg = read_experiment_with(&p, &spec, &opts("theta,alpha,Vm"))
        .unwrap_err()
        .to_string();
    assert!(msg.contains("row 3 (`alpha`) at sample 8"), "{msg}");

    // Too short.
    let p = write_bytes(
        "matbad5",
        "s.mat",
        &mat_file(&[matrix("d", 4, 5, &quarc_data(5))], false),
    );
    let msg = read_experiment_with(&p, &spec, &opts("theta,alpha,Vm"))
        .unwrap_err()
        .to_string();
    assert!(msg.contains("file too short: 5 samples"), "{msg}");

    // Mapping lacks a model channel.
    let p = write_bytes(
        "matbad6",
        "c.mat",
        &mat_file(&[matrix("d", 4, 30, &quarc_data(30))], false),
    );
    let msg = read_experiment_with(&p, &spec, &opts("theta,beta,Vm"))
        .unwrap_err()
        .to_string();
    assert!(msg.contains("missing column `alpha`"), "{msg}");

    // Not a MAT file at all.
    let p = write_bytes("matbad7", "x.mat", b"hello");
    assert!(read_experiment(&p, &spec).is_err());
}

#[test]
fn channel_map_argument() {
    assert_eq!(
        parse_channel_map("theta, alpha ,Vm").unwrap(),
        vec!["theta", "alpha", "Vm"]
    );
    assert!(parse_channel_map("theta,,Vm").is_err());
    assert!(parse_channel_map("theta,theta")
        .unwrap_err()
        .to_string()
        .contains("twice"));
}

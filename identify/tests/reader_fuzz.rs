//! Bounded fuzzing of the measurement readers (CI): byte-level mutants of a
//! good CSV file and of good MAT v5 files (plain and compressed), and a fixed
//! corpus of hostile files, are errors or experiments, never panics. Longer
//! runs: the `cargo fuzz` targets in `fuzz/` (see its README).

mod common;

use std::io::Write;

use common::*;
use plantc_identify::{parse_channel_map, read_experiment_with, ReadOptions};
use proptest::prelude::*;

/// One MAT v5 data element: tag, data, padding to 8 bytes.
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

/// A MAT v5 file with one real double matrix `rows x cols` (column-major).
fn mat(rows: i32, cols: i32, data: &[f64], compressed: bool) -> Vec<u8> {
    let mut body = Vec::new();
    body.extend(element(
        6,
        &[6u32.to_le_bytes(), 0u32.to_le_bytes()].concat(),
    ));
    body.extend(element(
        5,
        &[rows.to_le_bytes(), cols.to_le_bytes()].concat(),
    ));
    body.extend(element(1, b"data"));
    let real: Vec<u8> = data.iter().flat_map(|v| v.to_le_bytes()).collect();
    body.extend(element(9, &real));
    let e = element(14, &body);
    let mut out = b"MATLAB 5.0 MAT-file, Platform: GLNXA64, Created by: plantc fuzz".to_vec();
    out.resize(116, b' ');
    out.extend([0u8; 8]);
    out.extend(0x0100u16.to_le_bytes());
    out.extend(b"IM");
    if compressed {
        let mut enc = libflate::zlib::Encoder::new(Vec::new()).unwrap();
        enc.write_all(&e).unwrap();
        let z = enc.finish().into_result().unwrap();
        out.extend(15u32.to_le_bytes());
        out.extend((z.len() as u32).to_le_bytes());
        out.extend(z);
    } else {
        out.extend(e);
    }
    out
}

fn good_mat(compressed: bool) -> Vec<u8> {
    let n = 40;
    let data: Vec<f64> = (0..n)
        .flat_map(|k| [k as f64 * 0.002, 0.01 * k as f64, 3.1, 1.5])
        .collect();
    mat(4, n, &data, compressed)
}

fn options() -> ReadOptions {
    ReadOptions {
        mat_channels: Some(parse_channel_map("theta,alpha,Vm").unwrap()),
        rename: Vec::new(),
    }
}

/// Reads `bytes` as `name` through the public reader: must not panic.
fn read(test: &str, name: &str, bytes: &[u8]) {
    let p = scratch(test).join(name);
    std::fs::write(&p, bytes).unwrap();
    let r = read_experiment_with(&p, &pendulum_spec(), &options());
    if let Err(e) = r {
        // every error names its file
        assert!(e.to_string().contains(name), "{e}");
    }
}

#[derive(Debug, Clone)]
enum Edit {
    Flip(usize, u8),
    Insert(usize, Vec<u8>),
    Delete(usize, usize),
    Truncate(usize),
}

fn edit() -> impl Strategy<Value = Edit> {
    let pieces = prop_oneof![
        Just(b",".to_vec()),
        Just(b"\"".to_vec()),
        Just(b"\n".to_vec()),
        Just(b"\r".to_vec()),
        Just(b"NaN".to_vec()),
        Just(b"1e400".to_vec()),
        Just(b"-".to_vec()),
        Just(b"#".to_vec()),
        Just(b"[deg]".to_vec()),
        Just(vec![0xff, 0xfe]),
        Just(vec![0u8; 9]),
        Just(vec![0xff; 8]),
        proptest::collection::vec(any::<u8>(), 1..16),
    ];
    prop_oneof![
        (any::<usize>(), any::<u8>()).prop_map(|(a, b)| Edit::Flip(a, b)),
        (any::<usize>(), pieces).prop_map(|(a, p)| Edit::Insert(a, p)),
        (any::<usize>(), 1usize..64).prop_map(|(a, n)| Edit::Delete(a, n)),
        any::<usize>().prop_map(Edit::Truncate),
    ]
}

fn apply(mut b: Vec<u8>, edits: &[Edit]) -> Vec<u8> {
    for e in edits {
        let n = b.len().max(1);
        match e {
            Edit::Flip(a, v) => {
                if !b.is_empty() {
                    b[a % n] = *v;
                }
            }
            Edit::Insert(a, p) => {
                let at = a % (b.len() + 1);
                b.splice(at..at, p.iter().copied());
            }
            Edit::Delete(a, k) => {
                let at = a % n;
                let end = (at + k).min(b.len());
                if at < end {
                    b.drain(at..end);
                }
            }
            Edit::Truncate(a) => b.truncate(a % n),
        }
    }
    b
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

    #[test]
    fn mutated_csv_never_panics(edits in proptest::collection::vec(edit(), 1..6)) {
        read("fuzz_csv", "m.csv", &apply(good_csv(30).into_bytes(), &edits));
    }

    #[test]
    fn mutated_mat_never_panics(edits in proptest::collection::vec(edit(), 1..4), z in any::<bool>()) {
        read("fuzz_mat", "m.mat", &apply(good_mat(z), &edits));
    }
}

#[test]
fn hostile_corpus_is_errors_not_panics() {
    let mut corpus: Vec<(&str, Vec<u8>)> = vec![
        ("empty.csv", Vec::new()),
        ("header_only.csv", b"t,theta,alpha,Vm\n".to_vec()),
        (
            "bom.csv",
            [b"\xef\xbb\xbf".as_slice(), good_csv(20).as_bytes()].concat(),
        ),
        ("latin1.csv", b"t,theta,alpha,Vm\n0,\xe9,0,0\n".to_vec()),
        ("quote.csv", b"t,theta,alpha,Vm\n\"0,1,2,3\n".to_vec()),
        ("nul.csv", b"t,theta,alpha,Vm\n\0\0\0\n".to_vec()),
        ("cr_only.csv", good_csv(20).replace('\n', "\r").into_bytes()),
        (
            "long_field.csv",
            format!("t,theta,alpha,Vm\n{}\n", "9".repeat(1 << 20)).into_bytes(),
        ),
        (
            "many_columns.csv",
            format!("{}\n", vec!["x"; 100_000].join(",")).into_bytes(),
        ),
        ("empty.mat", Vec::new()),
        ("header_only.mat", good_mat(false)[..128].to_vec()),
        ("truncated.mat", good_mat(false)[..200].to_vec()),
        ("truncated_z.mat", good_mat(true)[..150].to_vec()),
    ];
    // dimensions that do not match the data, huge or negative
    for (rows, cols) in [
        (4, 1 << 30),
        (1 << 30, 4),
        (-4, 40),
        (0, 0),
        (4, 0),
        (1, 40),
    ] {
        let data: Vec<f64> = (0..160).map(f64::from).collect();
        corpus.push(("dims.mat", mat(rows, cols, &data, false)));
        corpus.push(("dims_z.mat", mat(rows, cols, &data, true)));
    }
    // a compressed element claiming a huge length
    let mut z = good_mat(true);
    z[132..136].copy_from_slice(&u32::MAX.to_le_bytes());
    corpus.push(("huge_len.mat", z));
    for (name, bytes) in corpus {
        read("corpus", name, &bytes);
    }
}

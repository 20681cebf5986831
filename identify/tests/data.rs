//! Reading CSV experiments: good files, unit suffixes, warnings and every bad-data case.

mod common;

use common::*;
use plantc_identify::{
    read_experiment, read_experiments, DataError, DataWarning, Experiment, ReadOptions,
};

/// Reads a file that must fail; returns the error and its Display text.
fn fail(test: &str, text: &str) -> (DataError, String) {
    let p = write(test, "bad.csv", text);
    let err = read_experiment(&p, &pendulum_spec()).expect_err("must fail");
    let msg = err.to_string();
    assert!(msg.contains("bad.csv"), "names the file: {msg}");
    assert!(msg.contains("help:"), "has help: {msg}");
    (err, msg)
}

#[test]
fn reads_good_file() {
    let p = write("good", "run.csv", &good_csv(20));
    let (e, w) = read_experiment(&p, &pendulum_spec()).unwrap();
    assert!(w.is_empty(), "{w:?}");
    assert_eq!(e.name, "run");
    assert_eq!(e.len(), 20);
    assert_eq!(e.channel_names(), vec!["theta", "alpha", "Vm"]);
    assert!((e.values("theta").unwrap()[3] - 0.03).abs() < 1e-12);
    assert!((e.sample_time().unwrap() - 0.002).abs() < 1e-12);
}

#[test]
fn columns_matched_by_name_and_extras_kept() {
    let mut s = String::from("Vm,current,alpha,t,theta\n");
    s += &rows(12, |k, t| format!("1.0,{k},3.0,{t},0.1"));
    let p = write("byname", "x.csv", &s);
    let (e, _) = read_experiment(&p, &pendulum_spec()).unwrap();
    assert_eq!(e.channel_names(), vec!["theta", "alpha", "Vm", "current"]);
    assert_eq!(e.values("current").unwrap()[5], 5.0);
    assert_eq!(e.values("Vm").unwrap()[0], 1.0);
}

#[test]
fn unit_suffixes_convert_to_si() {
    let mut s = String::from("t[ms],theta[rad],alpha[deg],Vm[V],x[mm],y[cm]\n");
    s += &rows(12, |k, _| format!("{},0.5,180,2,1500,250", 2 * k));
    let p = write("units", "u.csv", &s);
    let (e, w) = read_experiment(&p, &pendulum_spec()).unwrap();
    assert!(w.is_empty(), "{w:?}");
    assert!((e.t[1] - 0.002).abs() < 1e-15);
    assert!((e.values("alpha").unwrap()[0] - std::f64::consts::PI).abs() < 1e-12);
    assert_eq!(e.values("theta").unwrap()[0], 0.5);
    assert!((e.values("x").unwrap()[0] - 1.5).abs() < 1e-12);
    assert!((e.values("y").unwrap()[0] - 2.5).abs() < 1e-12);
    assert_eq!(
        e.channel("alpha").unwrap().unit_note.as_deref(),
        Some("deg -> rad")
    );
    assert_eq!(
        e.channel("theta").unwrap().unit_note.as_deref(),
        Some("rad")
    );
}

#[test]
fn length_coordinates_in_mm_and_cm() {
    let spec = plantc_identify::ChannelSpec::new()
        .length("x")
        .input("F", plantc_identify::Kind::Force);
    let mut s = String::from("t,x[cm],F[N]\n");
    s += &rows(12, |_, t| format!("{t},12.5,1"));
    let p = write("cm", "c.csv", &s);
    let (e, _) = read_experiment(&p, &spec).unwrap();
    assert!((e.values("x").unwrap()[0] - 0.125).abs() < 1e-15);
}

#[test]
fn several_files_are_several_experiments() {
    let a = write("several_a", "a.csv", &good_csv(15));
    let b = write("several_b", "b.csv", &good_csv(25));
    let (es, _) = read_experiments(&[a, b], &pendulum_spec(), &ReadOptions::default()).unwrap();
    assert_eq!(es.len(), 2);
    assert_eq!((es[0].name.as_str(), es[0].len()), ("a", 15));
    assert_eq!((es[1].name.as_str(), es[1].len()), ("b", 25));
}

#[test]
fn nan_cell_names_line_and_column() {
    let mut s = good_csv(20);
    s = s.replacen("0.040000,", "NaN,", 1); // theta at k=4: line 6
    let (e, msg) = fail("nan", &s);
    assert!(msg.contains("bad.csv:6:2:"), "{msg}");
    assert!(
        msg.contains("non-finite") && msg.contains("`theta`"),
        "{msg}"
    );
    assert_eq!((e.line(), e.column()), (Some(6), Some(2)));
}

#[test]
fn empty_cell_names_line_and_column() {
    let s = good_csv(20).replacen(",0.500\n", ",\n", 3); // Vm empty on lines 2..4
    let (_, msg) = fail("empty", &s);
    assert!(msg.contains("bad.csv:2:4:"), "{msg}");
    assert!(msg.contains("empty cell in column `Vm`"), "{msg}");
}

#[test]
fn short_row_is_a_field_count_error() {
    let s = good_csv(20).replacen(",0.500\n", "\n", 1);
    let (e, msg) = fail("shortrow", &s);
    assert!(
        msg.contains("bad.csv:2: ") && msg.contains("this row has 3 fields, the header has 4"),
        "{msg}"
    );
    assert!(matches!(e, DataError::FieldCount { found: 3, .. }));
}

/// Reliability reproducer 10: a decimal comma in one cell shifted the row
/// (alpha read 3, Vm read 14) and the rest was silently dropped.
#[test]
fn decimal_comma_row_is_an_error_with_a_hint() {
    let s = good_csv(20).replacen("3.103000", "3,14", 1);
    let (e, msg) = fail("decimal_comma", &s);
    assert!(msg.contains("bad.csv:5:3:"), "{msg}");
    assert!(
        msg.contains("this row has 5 fields, the header has 4"),
        "{msg}"
    );
    assert!(
        msg.contains("`3,14` looks like a number with a decimal comma"),
        "{msg}"
    );
    assert!(msg.contains("decimal point"), "{msg}");
    assert_eq!((e.line(), e.column()), (Some(5), Some(3)));
    // an extra field that is no decimal comma: still an error, no hint
    let s = good_csv(20).replacen(",0.500\n", ",0.500,x\n", 1);
    let (_, msg) = fail("extra_field", &s);
    assert!(
        msg.contains("bad.csv:2: ") && msg.contains("5 fields"),
        "{msg}"
    );
    assert!(!msg.contains("decimal comma"), "{msg}");
}

/// Reliability reproducer 16a: time logged in ms without a `t[ms]` suffix.
#[test]
fn time_in_milliseconds_without_suffix_warns() {
    let mut s = String::from("t,theta,alpha,Vm\n");
    s += &rows(20, |k, _| format!("{},0.01,3.1,0.5", 2 * k));
    let p = write("ms", "ms.csv", &s);
    let (_, w) = read_experiment(&p, &pendulum_spec()).unwrap();
    let text: Vec<String> = w.iter().map(|w| w.to_string()).collect();
    assert!(
        w.iter().any(|w| matches!(w, DataWarning::LooksLikeMilliseconds { median_dt, .. } if *median_dt == 2.0)),
        "{text:?}"
    );
    assert!(text.iter().any(|t| t.contains("write `t[ms]`")), "{text:?}");
    // with the suffix, or at a plausible rate, no warning
    let (_, w) = read_experiment(&write("ms2", "ok.csv", &good_csv(20)), &pendulum_spec()).unwrap();
    assert!(w.is_empty(), "{w:?}");
}

#[test]
fn unparsable_number() {
    let s = good_csv(20).replacen("3.103000", "3,1o3", 1);
    let (_, msg) = fail("unparsable", &s);
    // The comma splits the cell: the row has one field too many.
    assert!(msg.contains("bad.csv:5: "), "{msg}");
    assert!(msg.contains("5 fields"), "{msg}");
    let s = good_csv(20).replacen("3.103000", "3.1o3", 1);
    let (_, msg) = fail("unparsable2", &s);
    assert!(
        msg.contains("bad.csv:5:3:") && msg.contains("`alpha`"),
        "{msg}"
    );
}

#[test]
fn missing_column_lists_found_and_expected() {
    let mut s = String::from("t,theta,Vm,extra\n");
    s += &rows(12, |_, t| format!("{t},0,0,0"));
    let (e, msg) = fail("missing", &s);
    assert!(matches!(e, DataError::MissingColumn { .. }));
    assert!(msg.contains("missing column `alpha`"), "{msg}");
    assert!(msg.contains("found columns: t, theta, Vm, extra"), "{msg}");
    assert!(msg.contains("expected: t, theta, alpha, Vm"), "{msg}");
}

#[test]
fn missing_time_column() {
    let mut s = String::from("time,theta,alpha,Vm\n");
    s += &rows(12, |_, t| format!("{t},0,0,0"));
    let (_, msg) = fail("notime", &s);
    assert!(msg.contains("missing column `t`"), "{msg}");
}

#[test]
fn duplicate_time() {
    let s = good_csv(20).replacen("0.0060,", "0.0040,", 1); // line 5 repeats line 4
    let (e, msg) = fail("duptime", &s);
    assert!(
        msg.contains("bad.csv:5:1:") && msg.contains("duplicate time"),
        "{msg}"
    );
    assert!(matches!(e, DataError::TimeNotIncreasing { .. }));
}

#[test]
fn decreasing_time() {
    let s = good_csv(20).replacen("0.0060,", "0.0010,", 1);
    let (_, msg) = fail("backtime", &s);
    assert!(
        msg.contains("bad.csv:5:1:") && msg.contains("time goes backwards"),
        "{msg}"
    );
}

#[test]
fn too_short() {
    let (e, msg) = fail("short", &good_csv(9));
    assert!(
        msg.contains("file too short: 9 samples, at least 10"),
        "{msg}"
    );
    assert!(matches!(e, DataError::TooShort { samples: 9, .. }));
    let (_, msg) = fail("headeronly", "t,theta,alpha,Vm\n");
    assert!(msg.contains("0 samples"), "{msg}");
}

#[test]
fn empty_file() {
    let (e, msg) = fail("emptyfile", "");
    assert!(matches!(e, DataError::MissingColumn { .. }), "{msg}");
}

#[test]
fn unknown_unit_suffix() {
    let mut s = String::from("t,theta,alpha[grad],Vm\n");
    s += &rows(12, |_, t| format!("{t},0,0,0"));
    let (_, msg) = fail("unit", &s);
    assert!(msg.contains("bad.csv:1:3:"), "{msg}");
    assert!(msg.contains("unknown unit suffix `[grad]`"), "{msg}");
    assert!(msg.contains("deg"), "help lists known units: {msg}");
}

#[test]
fn incompatible_unit_suffix() {
    let mut s = String::from("t,theta[mm],alpha,Vm\n");
    s += &rows(12, |_, t| format!("{t},0,0,0"));
    let (_, msg) = fail("incompat", &s);
    assert!(
        msg.contains("bad.csv:1:2:") && msg.contains("length unit"),
        "{msg}"
    );
}

#[test]
fn duplicate_column() {
    let mut s = String::from("t,theta,alpha,theta[deg],Vm\n");
    s += &rows(12, |_, t| format!("{t},0,0,0,0"));
    let (_, msg) = fail("dupcol", &s);
    assert!(
        msg.contains("bad.csv:1:4:") && msg.contains("appears twice"),
        "{msg}"
    );
}

#[test]
fn missing_file_is_an_error() {
    let p = scratch("nofile").join("nope.csv");
    let err = read_experiment(&p, &pendulum_spec()).unwrap_err();
    assert!(err.to_string().contains("nope.csv"), "{err}");
}

#[test]
fn bad_extra_column_is_dropped_with_warning() {
    let mut s = String::from("t,theta,alpha,Vm,note\n");
    s += &rows(12, |k, t| {
        format!("{t},0,0,0,{}", if k == 3 { "x" } else { "1" })
    });
    let p = write("extra", "e.csv", &s);
    let (e, w) = read_experiment(&p, &pendulum_spec()).unwrap();
    assert!(e.channel("note").is_none());
    assert!(
        matches!(w[0], DataWarning::DroppedColumn { line: 5, .. }),
        "{w:?}"
    );
}

#[test]
fn degree_range_warning() {
    // A hanging pendulum swinging 60 deg, logged in degrees without suffix.
    let mut s = String::from("t,theta,alpha,Vm\n");
    s += &rows(1000, |_, t| {
        let a = 180.0 + 60.0 * (6.0 * t).cos();
        format!("{t:.4},0,{a:.6},0")
    });
    let p = write("degwarn", "d.csv", &s);
    let (_, w) = read_experiment(&p, &pendulum_spec()).unwrap();
    assert_eq!(w.len(), 1, "{w:?}");
    let text = w[0].to_string();
    assert!(
        text.contains("`alpha`") && text.contains("degrees"),
        "{text}"
    );
    assert!(text.contains("20 revolutions"), "{text}");
}

#[test]
fn degree_quantum_warning() {
    // Arm moving +-20 deg, 4096-count encoder, logged in degrees: small values,
    // caught by the encoder-quantum rule.
    let q = 360.0 / 4096.0;
    let mut s = String::from("t,theta,alpha,Vm\n");
    s += &rows(2000, |_, t| {
        let th = (20.0 * (2.0 * t).sin() / q).round() * q;
        format!("{t:.4},{th:.9},3.141592654,0")
    });
    let p = write("degq", "q.csv", &s);
    let (_, w) = read_experiment(&p, &pendulum_spec()).unwrap();
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(w[0].to_string().contains("360/4096"), "{}", w[0]);
}

#[test]
fn radians_do_not_warn() {
    // The same motion in radians, quantised at 2 pi/4096: no warning.
    let q = 2.0 * std::f64::consts::PI / 4096.0;
    let mut s = String::from("t,theta,alpha,Vm\n");
    s += &rows(2000, |_, t| {
        let th = (0.35 * (2.0 * t).sin() / q).round() * q;
        let a = ((std::f64::consts::PI + 1.0 * (6.0 * t).cos()) / q).round() * q;
        format!("{t:.4},{th:.9},{a:.9},0")
    });
    let p = write("radok", "r.csv", &s);
    let (_, w) = read_experiment(&p, &pendulum_spec()).unwrap();
    assert!(w.is_empty(), "{w:?}");
}

#[test]
fn shared_data_files_load() {
    let Some(dir) = shared_data() else {
        eprintln!("skipping: shared data folder not found (set PLANTC_DATA)");
        return;
    };
    for case in ["clean", "coulomb_pendulum", "spring_arm"] {
        for f in ["free_swing_large", "free_swing_small", "driven"] {
            let p = dir.join(case).join(format!("{f}.csv"));
            let (e, w) = read_experiment(&p, &pendulum_spec()).unwrap();
            // 10,001 lines: the header and 10,000 samples (t = 0 .. 19.998 s).
            assert_eq!(e.len(), 10_000, "{}", p.display());
            assert!(w.is_empty(), "{}: {w:?}", p.display());
            assert!((e.sample_time().unwrap() - 0.002).abs() < 1e-9);
        }
    }
}

/// Issue 31 (r10): one wrong stamp (1e6 s at the end of a 40 ms record) is
/// an error naming its line before anything is simulated; a comment line
/// before it keeps the line number right.
#[test]
fn a_time_gap_is_an_error_at_its_line() {
    let mut s = good_csv(20);
    s = s.replacen("0.0100,", "# a comment line\n0.0100,", 1);
    let last = s.lines().last().unwrap().to_string();
    let bad = format!("1000000.0{}", &last[last.find(',').unwrap()..]);
    s = s.replace(&last, &bad);
    let (e, msg) = fail("gap", &s);
    // 20 rows from line 2, one comment line: the last row is line 22
    assert!(msg.contains("bad.csv:22:"), "{msg}");
    assert!(
        msg.contains("the time jumps from 0.036 s to 1000000 s"),
        "{msg}"
    );
    assert!(matches!(e, DataError::TimeGap { sample: 20, .. }), "{e:?}");
    // dropped samples are not a gap: 500 missing periods are accepted
    let mut s = String::from("t,theta,alpha,Vm\n");
    s += &rows(30, |k, t| {
        let t = if k >= 15 { t + 1.0 } else { t };
        format!("{t},0.1,3.1,0.5")
    });
    let p = write("nogap", "ok.csv", &s);
    assert!(read_experiment(&p, &pendulum_spec()).is_ok());
}

/// Issue 31 (r08): a file without line breaks is refused at 1 MiB, not
/// read into one record of its size; FIFOs and devices are refused before
/// they are opened.
#[test]
fn endless_lines_and_non_regular_files_are_refused() {
    let p = write("longline", "zeros.csv", &"\0".repeat(3 << 20));
    let msg = read_experiment(&p, &pendulum_spec())
        .unwrap_err()
        .to_string();
    assert!(msg.contains("a line longer than 1 MiB"), "{msg}");
    #[cfg(unix)]
    {
        let msg = read_experiment(std::path::Path::new("/dev/zero"), &pendulum_spec())
            .unwrap_err()
            .to_string();
        assert!(msg.contains("not a regular file"), "{msg}");
        let fifo = scratch("fifo").join("pipe.csv");
        let _ = std::fs::remove_file(&fifo);
        assert!(std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success());
        let msg = read_experiment(&fifo, &pendulum_spec())
            .unwrap_err()
            .to_string();
        assert!(msg.contains("not a regular file"), "{msg}");
    }
}

/// Issue 31: a value whose square overflows (1e300) is an error at its
/// cell, not a NaN fit % later; in an extra column it drops the column.
#[test]
fn absurd_magnitudes_are_errors_at_their_cell() {
    let s = good_csv(20).replacen(",0.500", ",1e300", 1);
    let (e, msg) = fail("huge", &s);
    assert!(
        msg.contains("bad.csv:2:4:") && msg.contains("beyond 1e150"),
        "{msg}"
    );
    assert!(matches!(e, DataError::BadCell { .. }), "{e:?}");
    let mut s = String::from("t,theta,alpha,Vm,x\n");
    s += &rows(12, |k, t| {
        format!("{t},0.1,3.1,0.5,{}", if k == 3 { "1e200" } else { "1" })
    });
    let p = write("hugeextra", "x.csv", &s);
    let (e, w) = read_experiment(&p, &pendulum_spec()).unwrap();
    assert!(e.channel("x").is_none());
    assert!(
        w.iter()
            .any(|w| matches!(w, DataWarning::DroppedColumn { line: 5, .. })),
        "{w:?}"
    );
}

/// Inputs read as continuous signals: each sample becomes the mean of the
/// line through it and the next over its interval (the last is kept); the
/// other channels are left alone.
#[test]
fn continuous_inputs_are_interval_means() {
    let channel = |name: &str, values: &[f64]| plantc_identify::Channel {
        name: name.into(),
        unit_note: None,
        values: values.to_vec(),
    };
    let e = Experiment {
        name: "e".into(),
        file: "e.csv".into(),
        t: vec![0.0, 0.1, 0.3, 0.4],
        channels: vec![
            channel("theta", &[0.0, 1.0, 2.0, 3.0]),
            channel("Vm", &[0.0, 2.0, 4.0, 10.0]),
        ],
    };
    let c = e.with_continuous_inputs(&["Vm".to_string()]);
    assert_eq!(c.values("Vm").unwrap(), &[1.0, 3.0, 7.0, 10.0]);
    assert_eq!(c.values("theta").unwrap(), e.values("theta").unwrap());
    assert_eq!(c.t, e.t);
}

/// An angle written wrapped into one turn (a pendulum swinging through its
/// upright at pi, written in [-pi, pi)) is read unwrapped, with a warning
/// that names the column; degrees with a suffix are unwrapped after the
/// conversion, and the other channels are left alone.
#[test]
fn wrapped_angles_are_read_unwrapped() {
    use std::f64::consts::PI;
    let wrap = |a: f64| (a + PI).rem_euclid(2.0 * PI) - PI;
    // alpha swings 3.0 -> 3.5 -> 3.0 rad through pi: two wraps
    let truth = |k: usize| 3.0 + 0.5 * (PI * k as f64 / 19.0).sin();
    let mut s = String::from("t,theta,alpha[deg],Vm\n");
    s += &rows(20, |k, t| {
        format!("{t},0.1,{:.9},4.0", wrap(truth(k)).to_degrees())
    });
    let p = write("wrapped", "w.csv", &s);
    let (e, w) = read_experiment(&p, &pendulum_spec()).unwrap();
    let alpha = e.values("alpha").unwrap();
    for (k, a) in alpha.iter().enumerate() {
        assert!((a - truth(k)).abs() < 1e-8, "{k}: {a} vs {}", truth(k));
    }
    assert_eq!(w.len(), 1, "{w:?}");
    let msg = w[0].to_string();
    assert!(
        msg.contains("`alpha`") && msg.contains("2 time(s)"),
        "{msg}"
    );
    assert_eq!(e.values("Vm").unwrap()[3], 4.0);
    // a swing that stays within half a turn per sample is left alone
    let mut v = vec![0.0, 3.0, 6.0, 3.0];
    assert_eq!(plantc_identify::unwrap_angle(&mut v), 0);
    assert_eq!(v, vec![0.0, 3.0, 6.0, 3.0]);
}

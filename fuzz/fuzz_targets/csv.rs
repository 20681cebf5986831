//! A measurement file (CSV) through the reader: errors are fine, panics are bugs.
#![no_main]

use libfuzzer_sys::fuzz_target;
use plantc_identify::{parse_channel_map, read_experiment_with, ChannelSpec, Kind, ReadOptions};

fuzz_target!(|data: &[u8]| {
    // the readers take paths: one scratch file per fuzzing process
    let path = std::env::temp_dir().join(format!("plantc-fuzz-{}.csv", std::process::id()));
    if std::fs::write(&path, data).is_err() {
        return;
    }
    let spec = ChannelSpec::new()
        .angle("theta")
        .angle("alpha")
        .input("Vm", Kind::Voltage);
    let options = ReadOptions {
        mat_channels: parse_channel_map("theta,alpha,Vm").ok(),
        ..ReadOptions::default()
    };
    let _ = read_experiment_with(&path, &spec, &options);
});

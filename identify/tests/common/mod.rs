//! Helpers shared by the integration tests.
#![allow(dead_code)]

pub mod simulated;

use std::path::PathBuf;

use plantc_identify::synth::{parse_effect_spec, parse_experiment_spec};
use plantc_identify::{
    read_experiment, synthesize, ChannelSpec, Experiment, Kind, SynthOptions, SynthSpec,
    Synthesized,
};

/// The rotary pendulum's channels.
pub fn pendulum_spec() -> ChannelSpec {
    ChannelSpec::new()
        .angle("theta")
        .angle("alpha")
        .input("Vm", Kind::Voltage)
}

/// The text of the bundled model `models/NAME` (e.g. `pendubot.plant`).
pub fn bundled_model(name: &str) -> String {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../models")
        .join(name);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("models/{name}: {e}"))
}

/// A synth spec for `case`: the bundled `model_name` (e.g.
/// `pendubot.plant`) at the true `values` with `effects` hidden and
/// `experiments`, both spelled as `plantc synth` takes them, the noise
/// and the multisines' phases drawn from `seed`.
pub fn synth_spec(
    case: &str,
    model_name: &str,
    effects: &[&str],
    values: &[(&str, f64)],
    experiments: &[&str],
    seed: u64,
) -> SynthSpec {
    SynthSpec {
        case: case.into(),
        model_name: model_name.into(),
        effects: effects
            .iter()
            .map(|e| parse_effect_spec(e).expect("effect"))
            .collect(),
        parameter_set: None,
        values: values.iter().map(|(n, v)| (n.to_string(), *v)).collect(),
        experiments: experiments
            .iter()
            .map(|e| parse_experiment_spec(e).expect("experiment"))
            .collect(),
        options: SynthOptions {
            seed,
            ..SynthOptions::default()
        },
    }
}

/// A fresh scratch directory for one test.
pub fn scratch(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("plantc-identify-{}-{}", std::process::id(), test));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("create scratch dir");
    dir
}

/// Writes a file in a scratch directory and returns its path.
pub fn write(test: &str, name: &str, text: &str) -> PathBuf {
    let p = scratch(test).join(name);
    std::fs::write(&p, text).expect("write test file");
    p
}

/// A good CSV body of `n` rows at 500 Hz, header given.
pub fn rows(n: usize, f: impl Fn(usize, f64) -> String) -> String {
    (0..n)
        .map(|k| {
            let t = k as f64 * 0.002;
            format!("{}\n", f(k, t))
        })
        .collect()
}

/// A good pendulum CSV with `n` rows.
pub fn good_csv(n: usize) -> String {
    let mut s = String::from("t,theta,alpha,Vm\n");
    s += &rows(n, |k, t| {
        format!(
            "{t:.4},{:.6},{:.6},{:.3}",
            0.01 * k as f64,
            3.1 + 0.001 * k as f64,
            0.5
        )
    });
    s
}

/// The shared data folder, if present.
pub fn shared_data() -> Option<PathBuf> {
    if let Some(d) = std::env::var_os("PLANTC_DATA") {
        return Some(PathBuf::from(d));
    }
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data");
    let p2 = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data");
    [p, p2].into_iter().find(|p| p.join("clean").is_dir())
}

/// Two short records of the rotary pendulum model `text` made by `synth`
/// ([`synth_pendulum`], noise seed 3): a run from rest, hanging, driven by
/// a random voltage (`driven`), and a free swing released from 120 degrees
/// (`swing`), 6 s each; the scratch directory removed again.
pub fn short_pendulum_records(
    test: &str,
    text: &str,
    effect: &str,
    values: Vec<(String, f64)>,
) -> Vec<Experiment> {
    let experiments = [
        "driven:alpha0=180deg,duration=6,seed=7,rms=1.2,name=driven",
        "free_swing:alpha0=120deg,duration=6,name=swing",
    ]
    .map(String::from);
    let exps = synth_pendulum(test, text, effect, values, &experiments, 3);
    let _ = std::fs::remove_dir_all(scratch(test));
    exps
}

/// Data of the rotary pendulum model `text` made by `synth` in scratch
/// directory `test`: `effect` hidden (empty: none), true `values`, the
/// `experiments` specs, 500 Hz and 4096 counts with noise seed `seed`.
pub fn synth_pendulum(
    test: &str,
    text: &str,
    effect: &str,
    values: Vec<(String, f64)>,
    experiments: &[String],
    seed: u64,
) -> Vec<Experiment> {
    let effects: Vec<&str> = Some(effect).filter(|e| !e.is_empty()).into_iter().collect();
    let values: Vec<(&str, f64)> = values.iter().map(|(n, v)| (n.as_str(), *v)).collect();
    let experiments: Vec<&str> = experiments.iter().map(String::as_str).collect();
    let spec = synth_spec(
        test,
        "rotary_pendulum.plant",
        &effects,
        &values,
        &experiments,
        seed,
    );
    synthesized(test, text, &spec)
}

/// Write `out`'s files in the test's scratch directory and read them back
/// as the CLI would, with `channels`.
pub fn read_back(test: &str, out: &Synthesized, channels: &ChannelSpec) -> Vec<Experiment> {
    let dir = scratch(test);
    out.files
        .iter()
        .map(|f| {
            let p = dir.join(&f.file_name);
            std::fs::write(&p, &f.text).expect("writes");
            read_experiment(&p, channels).expect("reads").0
        })
        .collect()
}

/// Synthesise `spec` from model `text`, write its files in the test's
/// scratch directory and read them back as the CLI would (the pendulum's
/// channels).
pub fn synthesized(test: &str, text: &str, spec: &SynthSpec) -> Vec<Experiment> {
    read_back(
        test,
        &synthesize(text, spec).expect("synthesizes"),
        &pendulum_spec(),
    )
}

/// The identify story of `text` on `exps` with the default options, its
/// rounds printed ([`show_rounds`]).
pub fn identify(text: &str, exps: &[Experiment]) -> plantc_identify::Story {
    let story = plantc_identify::identify(
        text,
        exps,
        &plantc_identify::StoryOptions::default(),
        &mut |_| {},
    )
    .expect("identifies");
    show_rounds(&story);
    story
}

/// The fitted value of parameter `name` in `story`'s final model (None
/// when that model has no such parameter).
pub fn final_value(story: &plantc_identify::Story, name: &str) -> Option<f64> {
    let model = plantc_identify::diagnose::model_from_text("final", &story.text).expect("checks");
    model
        .parameters
        .iter()
        .position(|p| p.name == name)
        .map(|i| story.fit.base[i])
}

/// Print each round of a story (effect, cost before and after) to stderr.
pub fn show_rounds(story: &plantc_identify::Story) {
    for (k, r) in story.rounds.iter().enumerate() {
        eprintln!(
            "round {}: {:?}, cost {:.3e} -> {:?}",
            k + 1,
            r.effect.as_ref().map(|e| e.label()),
            r.cost_before,
            r.cost_after
        );
    }
}

/// The effects a story ends with (`Story::effects`: those its rounds named
/// as its end steps left them), as `effect@target` labels in the order
/// named.
pub fn final_effects(story: &plantc_identify::Story) -> Vec<String> {
    story.effects.iter().map(|e| e.label()).collect()
}

/// `models/double_pendulum.plant`'s text with its dry friction taken out
/// (the `Fc` parameters and their `coulomb_friction` terms): viscous
/// friction only.
pub fn double_pendulum_without_dry_friction() -> String {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../models/double_pendulum.plant");
    let full = std::fs::read_to_string(path).expect("models/double_pendulum.plant");
    let text: String = full
        .lines()
        .filter(|l| !l.starts_with("parameter Fc"))
        .map(|l| {
            l.replace(" + coulomb_friction(Fc1)", "")
                .replace(" + coulomb_friction(Fc2)", "")
        })
        .collect::<Vec<_>>()
        .join("\n");
    assert!(!text.contains("coulomb"), "{text}");
    text
}

//! Snapshot tests: every `tests/malformed/*.plant` file produces rendered
//! diagnostics that are compared with `tests/snapshots/`.

use plantc_derive::lang::{parse_and_check, render, SourceFile};

#[test]
fn malformed_files_render_diagnostics() {
    let dir = format!("{}/tests/malformed", env!("CARGO_MANIFEST_DIR"));
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "plant"))
        .collect();
    files.sort();
    assert!(files.len() >= 18, "expected at least 18 malformed files");
    for path in files {
        let name = path.file_stem().unwrap().to_str().unwrap().to_string();
        let text = std::fs::read_to_string(&path).unwrap();
        let file_name = format!("{name}.plant");
        let checked = parse_and_check(&file_name, &text);
        assert!(checked.has_errors(), "{name}: expected at least one error");
        let rendered = render(&SourceFile::new(file_name, text), &checked.diagnostics);
        insta::assert_snapshot!(name, rendered);
    }
}

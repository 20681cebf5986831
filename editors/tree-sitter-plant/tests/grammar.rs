//! The tree-sitter grammar against the real parser: every model file of the
//! repository that `plantc`'s parser accepts parses with no ERROR or MISSING
//! node; the corpus tests (`test/corpus/*.txt`) give their trees; the
//! highlight query compiles against the grammar; and the grammar, the
//! highlight query and the VS Code grammar name every keyword, built-in and
//! effect the language has.
//!
//! Runs without the tree-sitter CLI: the generated parser (`src/`) is
//! committed (`generate.sh` remakes it with the pinned CLI).

use std::path::{Path, PathBuf};
use tree_sitter::{Language, Node, Parser, Query};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn grammar_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn language() -> Language {
    tree_sitter_plant::LANGUAGE.into()
}

fn parser() -> Parser {
    let mut p = Parser::new();
    p.set_language(&language()).expect("ABI of src/parser.c");
    p
}

/// Every `*.plant` under `dir`, skipping build output, dependencies and
/// hidden directories.
fn plant_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let mut entries: Vec<PathBuf> = entries.filter_map(|e| e.ok().map(|e| e.path())).collect();
    entries.sort();
    for p in entries {
        let name = p.file_name().and_then(|n| n.to_str()).unwrap_or("");
        if p.is_dir() {
            if !(name.starts_with('.') || name == "target" || name == "node_modules") {
                plant_files(&p, out);
            }
        } else if name.ends_with(".plant") {
            out.push(p);
        }
    }
}

/// The ```` ```plant ```` blocks of the documentation (the tutorial's model).
fn doc_blocks() -> Vec<(String, String)> {
    let mut out = Vec::new();
    let mut docs = vec![root().join("README.md")];
    if let Ok(rd) = std::fs::read_dir(root().join("docs")) {
        docs.extend(rd.filter_map(|e| e.ok().map(|e| e.path())));
    }
    docs.sort();
    for d in docs
        .iter()
        .filter(|d| d.extension().is_some_and(|x| x == "md"))
    {
        let text = std::fs::read_to_string(d).unwrap_or_default();
        let mut block: Option<(usize, String)> = None;
        for (i, line) in text.lines().enumerate() {
            match &mut block {
                None if line.trim() == "```plant" => block = Some((i + 1, String::new())),
                Some((start, b)) if line.trim() == "```" => {
                    out.push((format!("{}:{}", d.display(), *start), std::mem::take(b)));
                    block = None;
                }
                Some((_, b)) => {
                    b.push_str(line);
                    b.push('\n');
                }
                None => {}
            }
        }
    }
    out
}

/// The first ERROR or MISSING nodes of a tree, as `line:col kind`.
fn errors(node: Node, out: &mut Vec<String>) {
    if out.len() >= 5 {
        return;
    }
    if node.is_error() || node.is_missing() {
        let p = node.start_position();
        out.push(format!(
            "{}:{} {}",
            p.row + 1,
            p.column + 1,
            if node.is_missing() {
                format!("MISSING {}", node.kind())
            } else {
                "ERROR".to_string()
            }
        ));
        return;
    }
    if node.has_error() {
        let mut c = node.walk();
        for child in node.children(&mut c) {
            errors(child, out);
        }
    }
}

/// Whether plantc's own parser accepts `text` (syntax only; names and units
/// are `check`'s business, which the grammar does not do).
fn plantc_parses(text: &str) -> bool {
    plantc_derive::lang::parser::parse(text).1.is_empty()
}

#[test]
fn every_model_the_parser_accepts_parses_without_error_nodes() {
    let mut files = Vec::new();
    plant_files(&root(), &mut files);
    let mut inputs: Vec<(String, String)> = files
        .iter()
        .map(|p| {
            let name = p.strip_prefix(root()).unwrap_or(p).display().to_string();
            (name, std::fs::read_to_string(p).expect("read"))
        })
        .collect();
    inputs.extend(doc_blocks());
    let mut parser = parser();
    let (mut checked, mut failures) = (0, Vec::new());
    for (name, text) in &inputs {
        let accepted = plantc_parses(text);
        // the bundled models must be valid, so that they are checked here
        assert!(
            accepted || !name.starts_with("models/"),
            "{name}: plantc's parser rejects a bundled model"
        );
        if !accepted {
            continue;
        }
        checked += 1;
        let tree = parser.parse(text, None).expect("parse");
        let mut e = Vec::new();
        errors(tree.root_node(), &mut e);
        if !e.is_empty() {
            failures.push(format!("{name}: {}", e.join(", ")));
        }
    }
    // models/ (10 today) and the test fixtures at least
    assert!(checked >= 12, "only {checked} model files found");
    assert!(failures.is_empty(), "ERROR nodes:\n{}", failures.join("\n"));
}

/// `(a  (b\n c))` -> `(a (b c))`.
fn normalize(sexp: &str) -> String {
    let collapsed = sexp.split_whitespace().collect::<Vec<_>>().join(" ");
    collapsed.replace("( ", "(").replace(" )", ")")
}

/// `(a name: (b))` -> `(a (b))`.
fn without_fields(sexp: &str) -> String {
    sexp.split(' ')
        .filter(|w| !w.ends_with(':'))
        .collect::<Vec<_>>()
        .join(" ")
}

/// The tests of a corpus file: (name, input, expected tree).
fn corpus_tests(text: &str) -> Vec<(String, String, String)> {
    let lines: Vec<&str> = text.lines().collect();
    let is_rule = |l: &str, c: char| l.len() >= 3 && l.chars().all(|x| x == c);
    let mut tests = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        if is_rule(lines[i], '=') && i + 2 < lines.len() && is_rule(lines[i + 2], '=') {
            let name = lines[i + 1].trim().to_string();
            let mut j = i + 3;
            let mut input = Vec::new();
            while j < lines.len() && !is_rule(lines[j], '-') {
                input.push(lines[j]);
                j += 1;
            }
            let mut k = j + 1;
            let mut expected = Vec::new();
            while k < lines.len()
                && !(is_rule(lines[k], '=') && k + 2 < lines.len() && is_rule(lines[k + 2], '='))
            {
                expected.push(lines[k]);
                k += 1;
            }
            tests.push((
                name,
                input.join("\n").trim().to_string() + "\n",
                normalize(&expected.join("\n")),
            ));
            i = k;
        } else {
            i += 1;
        }
    }
    tests
}

#[test]
fn corpus_tests_give_their_trees() {
    let dir = grammar_dir().join("test/corpus");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .expect("test/corpus")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .collect();
    files.sort();
    let mut parser = parser();
    let mut n = 0;
    let mut failures = Vec::new();
    for f in files {
        for (name, input, expected) in corpus_tests(&std::fs::read_to_string(&f).unwrap()) {
            n += 1;
            let tree = parser.parse(&input, None).expect("parse");
            let mut got = normalize(&tree.root_node().to_sexp());
            // as the CLI: field names are compared only when the expected
            // tree has them
            if !expected.contains(": (") {
                got = without_fields(&got);
            }
            if got != expected {
                failures.push(format!(
                    "{} / {name}:\n  expected {expected}\n  got      {got}",
                    f.display()
                ));
            }
        }
    }
    assert!(n >= 10, "only {n} corpus tests found");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn the_highlight_query_compiles_against_the_grammar() {
    Query::new(&language(), tree_sitter_plant::HIGHLIGHTS_QUERY)
        .unwrap_or_else(|e| panic!("queries/highlights.scm: {e}"));
}

/// Keywords the parser recognises by context (not in `parser::KEYWORDS`).
const CONTEXTUAL: &[&str] = &[
    "limits",
    "estimate",
    "place",
    "poles",
    "lqr",
    "gains",
    "linearize",
    "gain",
    "surface",
    "mode",
    "switch",
    "wrap",
    "when",
    "and",
    "or",
    "swing_up",
    "signal",
];

#[test]
fn grammar_highlights_and_vscode_name_the_whole_language() {
    use plantc_derive::lang::{check::BUILTINS, effects::EFFECTS, parser::KEYWORDS};
    let dir = grammar_dir();
    let grammar = std::fs::read_to_string(dir.join("grammar.js")).unwrap();
    let generated = std::fs::read_to_string(dir.join("src/grammar.json")).unwrap();
    let highlights = tree_sitter_plant::HIGHLIGHTS_QUERY;
    let vscode =
        std::fs::read_to_string(root().join("editors/vscode/syntaxes/plant.tmLanguage.json"))
            .unwrap();
    let mut missing = Vec::new();
    for kw in KEYWORDS.iter().chain(CONTEXTUAL) {
        if !grammar.contains(&format!("'{kw}'")) {
            missing.push(format!("grammar.js: keyword `{kw}`"));
        }
        if !generated.contains(&format!("\"value\": \"{kw}\"")) {
            missing.push(format!(
                "src/grammar.json: keyword `{kw}` (run generate.sh after editing grammar.js)"
            ));
        }
        if !highlights.contains(&format!("\"{kw}\"")) {
            missing.push(format!("queries/highlights.scm: keyword `{kw}`"));
        }
        if !vscode.contains(kw) {
            missing.push(format!("vscode grammar: keyword `{kw}`"));
        }
    }
    let functions = BUILTINS
        .iter()
        .map(|(n, _)| *n)
        .chain(["sat", "energy", "derivative"])
        .chain(EFFECTS.iter().map(|e| e.name));
    for f in functions {
        if !highlights.contains(f) {
            missing.push(format!("queries/highlights.scm: function `{f}`"));
        }
        if !vscode.contains(f) {
            missing.push(format!("vscode grammar: function `{f}`"));
        }
    }
    // every rule of grammar.js is in the generated parser's grammar
    let rules = grammar.split_once("rules: {").map_or("", |(_, r)| r);
    for line in rules.lines() {
        let t = line.trim_start();
        if let Some((rule, _)) = t.split_once(": $ =>").or_else(|| t.split_once(": _ =>")) {
            if rule.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
                && !generated.contains(&format!("\"{rule}\": {{"))
            {
                missing.push(format!(
                    "src/grammar.json: rule `{rule}` (run generate.sh after editing grammar.js)"
                ));
            }
        }
    }
    assert!(missing.is_empty(), "{}", missing.join("\n"));
}

//! The server's answers on small files, through [`plantc_lsp::State`]
//! (the dispatch the server loop uses), without a connection.

use lsp_server::{Notification, Request, RequestId};
use plantc_lsp::State;
use serde_json::{json, Value};

const URI: &str = "file:///t/m.plant";

fn open(text: &str) -> (State, Vec<Value>) {
    let mut s = State::default();
    let out = s.notify(Notification::new(
        "textDocument/didOpen".into(),
        json!({"textDocument": {"uri": URI, "languageId": "plant", "version": 1, "text": text}}),
    ));
    let diags = out[0].params["diagnostics"].as_array().unwrap().clone();
    (s, diags)
}

fn req(s: &State, method: &str, params: Value) -> Value {
    let r = s.request(Request::new(RequestId::from(7), method.into(), params));
    r.response_result
        .unwrap_or_else(|e| panic!("{method}: {}", e.message))
}

/// Position just after the `nth` occurrence of `needle` (ASCII texts).
fn after(text: &str, needle: &str) -> Value {
    let at = text.find(needle).unwrap() + needle.len();
    let line = text[..at].matches('\n').count();
    let col = at - text[..at].rfind('\n').map_or(0, |i| i + 1);
    json!({"line": line, "character": col})
}

fn complete(text: &str, needle: &str) -> Vec<String> {
    let (s, _) = open(text);
    let r = req(
        &s,
        "textDocument/completion",
        json!({"textDocument": {"uri": URI}, "position": after(text, needle)}),
    );
    r.as_array()
        .unwrap()
        .iter()
        .map(|i| i["label"].as_str().unwrap().to_string())
        .collect()
}

const SMALL: &str = "model m\ncoordinate q : angle\ninput u [N*m]\nparameter m = 1 [kg] \"mass\" estimate [0.5, 2]\nparameter l = 0.5 [m]\nlet I = m*l^2\nkinetic T = 1/2*I*q'^2\nforce q = u\nset s { l = 0.6 [m] }\n";

#[test]
fn completion_follows_the_context() {
    // units inside brackets after a number
    let t = format!("{SMALL}parameter k = 2 [N*\n");
    let c = complete(&t, "[N*");
    assert!(
        c.contains(&"kg".to_string()) && c.contains(&"rad".to_string()),
        "{c:?}"
    );
    // statement keywords at the start of a line
    let t = format!("{SMALL}pa\n");
    let c = complete(&t, "\npa");
    assert!(c.contains(&"parameter".to_string()) && c.contains(&"controller".to_string()));
    // the kind of a coordinate
    let t = format!("{SMALL}coordinate x : \n");
    assert_eq!(complete(&t, "coordinate x : "), ["angle", "length"]);
    // sensor effects and parameters after `sensor q =`
    let t = format!("{SMALL}sensor q = \n");
    let c = complete(&t, "sensor q = ");
    assert!(
        c.contains(&"sensor_offset".to_string()) && !c.contains(&"viscous_friction".to_string())
    );
    assert!(c.contains(&"m".to_string()));
    // controller statements inside a controller block
    let t = format!("{SMALL}controller c {{\n    \n}}\n");
    let c = complete(&t, "controller c {\n    ");
    assert!(
        c.contains(&"place".to_string()) && c.contains(&"lqr".to_string()),
        "{c:?}"
    );
    // parameters in a set block
    let t = format!("{SMALL}set t {{\n    \n}}\n");
    let c = complete(&t, "set t {\n    ");
    assert_eq!(c, ["m", "l"]);
    // names and functions in an expression
    let c = complete(SMALL, "let I = m*");
    for n in ["q", "u", "m", "l", "I", "sin", "pi"] {
        assert!(c.contains(&n.to_string()), "{n} in {c:?}");
    }
}

#[test]
fn quick_fixes_add_a_missing_unit_and_fix_a_keyword() {
    let t = SMALL.replace("l = 0.6 [m]", "l = 0.6");
    let (s, d) = open(&t);
    let e = d
        .iter()
        .find(|d| d["code"] == "plantc::unit_mismatch")
        .unwrap();
    let a = req(
        &s,
        "textDocument/codeAction",
        json!({"textDocument": {"uri": URI}, "range": e["range"], "context": {"diagnostics": []}}),
    );
    assert_eq!(a[0]["title"], "Add the unit `[m]`");
    assert_eq!(a[0]["edit"]["changes"][URI][0]["newText"], " [m]");

    let t = SMALL.replace("kinetic T", "kinetik T");
    let (s, d) = open(&t);
    assert_eq!(d[0]["message"], "expected a declaration, found `kinetik`");
    let a = req(
        &s,
        "textDocument/codeAction",
        json!({"textDocument": {"uri": URI}, "range": d[0]["range"], "context": {"diagnostics": []}}),
    );
    assert_eq!(a[0]["title"], "Replace `kinetik` with `kinetic`");

    // unit fixes keep the dimension the text meant (units::readings)
    let fixes = |unit: &str| {
        let t = SMALL.replace("[kg]", unit);
        let (s, d) = open(&t);
        let a = req(
            &s,
            "textDocument/codeAction",
            json!({"textDocument": {"uri": URI}, "range": d[0]["range"], "context": {"diagnostics": []}}),
        );
        a.as_array()
            .unwrap()
            .iter()
            .map(|x| {
                x["edit"]["changes"][URI][0]["newText"]
                    .as_str()
                    .unwrap()
                    .to_string()
            })
            .collect::<Vec<_>>()
    };
    // `[kgm^2]` is kg*m^2, never kg
    assert_eq!(fixes("[kgm^2]"), vec!["kg*m"]);
    assert_eq!(fixes("[kgg]"), vec!["kg"]);
    // kg*s or a plural kg: not known, so no fix
    assert!(fixes("[kgs]").is_empty());
}

#[test]
fn semantic_tokens_classify_names() {
    let (s, _) = open(SMALL);
    let r = req(
        &s,
        "textDocument/semanticTokens/full",
        json!({"textDocument": {"uri": URI}}),
    );
    let data: Vec<u64> = r["data"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap())
        .collect();
    // decode to absolute (line, col, len, type, modifiers)
    let (mut line, mut col) = (0, 0);
    let mut toks = Vec::new();
    for c in data.chunks(5) {
        if c[0] > 0 {
            col = 0;
        }
        line += c[0];
        col += c[1];
        toks.push((line, col, c[2], c[3], c[4]));
    }
    let lines: Vec<&str> = SMALL.lines().collect();
    let text_of =
        |t: &(u64, u64, u64, u64, u64)| &lines[t.0 as usize][t.1 as usize..(t.1 + t.2) as usize];
    let find = |word: &str, line: u64| {
        toks.iter()
            .find(|t| t.0 == line && text_of(t) == word)
            .copied()
    };
    // legend: 0 keyword, 1 variable, 2 parameter, 3 property, 6 type, 7 number, 8 string
    assert_eq!(find("parameter", 3).unwrap().3, 0);
    let m = find("m", 3).unwrap();
    assert_eq!((m.3, m.4 & 1), (2, 1), "parameter, declaration");
    assert_eq!(find("kg", 3).unwrap().3, 6);
    assert_eq!(find("\"mass\"", 3).unwrap().3, 8);
    assert_eq!(find("q", 6).unwrap().3, 1, "coordinate use");
    assert_eq!(find("u", 7).unwrap().3, 3, "input use");
}

#[test]
fn hover_rename_and_formatting_edge_cases() {
    let (s, _) = open(SMALL);
    let h = req(
        &s,
        "textDocument/hover",
        json!({"textDocument": {"uri": URI}, "position": after(SMALL, "[k")}),
    );
    assert!(
        h["contents"]["value"]
            .as_str()
            .unwrap()
            .contains("kilogram"),
        "{h}"
    );
    let h = req(
        &s,
        "textDocument/hover",
        json!({"textDocument": {"uri": URI}, "position": after(SMALL, "let I = m*l^2\nkinetic T = 1/2*I*q")}),
    );
    assert!(h["contents"]["value"]
        .as_str()
        .unwrap()
        .contains("coordinate q : angle"));
    // built-ins cannot be renamed; names can
    let t = format!("{SMALL}let z = sin(q)\n");
    let (s, _) = open(&t);
    let p = req(
        &s,
        "textDocument/prepareRename",
        json!({"textDocument": {"uri": URI}, "position": after(&t, "z = si")}),
    );
    assert!(p.is_null());
    let p = req(
        &s,
        "textDocument/prepareRename",
        json!({"textDocument": {"uri": URI}, "position": after(&t, "let I")}),
    );
    assert_eq!(p["placeholder"], "I");
    // formatting a file with syntax errors changes nothing
    let (s, d) = open("model m\nlet x = (a +\n");
    assert!(!d.is_empty());
    let f = req(
        &s,
        "textDocument/formatting",
        json!({"textDocument": {"uri": URI}, "options": {"tabSize": 4, "insertSpaces": true}}),
    );
    assert_eq!(f, json!([]));
    let h = req(
        &s,
        "textDocument/inlayHint",
        json!({"textDocument": {"uri": URI}, "range": {"start": {"line": 0, "character": 0}, "end": {"line": 9, "character": 0}}}),
    );
    assert_eq!(h, json!([]));
}

#[test]
fn a_change_without_range_replaces_the_text() {
    let (mut s, _) = open(SMALL);
    let out = s.notify(Notification::new(
        "textDocument/didChange".into(),
        json!({"textDocument": {"uri": URI, "version": 2}, "contentChanges": [{"text": "model m\n"}]}),
    ));
    let d = out[0].params["diagnostics"].as_array().unwrap();
    assert_eq!(out[0].params["version"], 2);
    // the new text's own diagnostics (check also requires a coordinate)
    let messages: Vec<&str> = d.iter().filter_map(|x| x["message"].as_str()).collect();
    assert!(
        messages.contains(&"the model has no kinetic energy"),
        "{messages:?}"
    );
    // an unknown method is an error reply, not a crash
    let r = s.request(Request::new(
        RequestId::from(1),
        "textDocument/foo".into(),
        json!({}),
    ));
    assert!(r.response_result.is_err());
}

mod fuzz {
    use super::*;
    use proptest::prelude::*;

    const MODEL: &str = include_str!("../../models/rotary_pendulum.plant");
    const PIECES: &[&str] = &[
        "(",
        ")",
        "[",
        "]",
        "{",
        "}",
        "'",
        "^",
        "*",
        "+",
        "-",
        "=",
        ",",
        "\n",
        "\"",
        "#",
        "α",
        "1e-3",
        "2+3i",
        "theta",
        "alpha'",
        "sin(",
        "viscous_friction(",
        "[kg*m^2]",
        "parameter ",
        "let x = ",
        "controller c {",
        "set s {",
        "    ",
        "𝜃",
    ];

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(128))]

        /// Edits anywhere, then every request anywhere: always an answer.
        #[test]
        fn every_request_answers_on_edited_files(
            edits in prop::collection::vec((any::<prop::sample::Index>(), 0..PIECES.len(), 0usize..4), 1..6),
            probes in prop::collection::vec((0u32..90, 0u32..120), 1..6),
        ) {
            let mut text = MODEL.to_string();
            for (at, piece, del) in edits {
                let mut i = at.index(text.len() + 1);
                while !text.is_char_boundary(i) { i -= 1; }
                let mut j = (i + del).min(text.len());
                while !text.is_char_boundary(j) { j -= 1; }
                text.replace_range(i..j.max(i), PIECES[piece]);
            }
            let (s, _) = open(&text);
            for (line, character) in probes {
                let pos = json!({"line": line, "character": character});
                let tdp = json!({"textDocument": {"uri": URI}, "position": pos});
                for m in ["textDocument/hover", "textDocument/definition", "textDocument/completion",
                          "textDocument/prepareRename"] {
                    req(&s, m, tdp.clone());
                }
                let range = json!({"start": {"line": 0, "character": 0}, "end": pos});
                req(&s, "textDocument/references", json!({"textDocument": {"uri": URI}, "position": pos, "context": {"includeDeclaration": true}}));
                req(&s, "textDocument/codeAction", json!({"textDocument": {"uri": URI}, "range": range, "context": {"diagnostics": []}}));
                req(&s, "textDocument/inlayHint", json!({"textDocument": {"uri": URI}, "range": range}));
                let r = s.request(Request::new(RequestId::from(1), "textDocument/rename".into(),
                    json!({"textDocument": {"uri": URI}, "position": pos, "newName": "zz"})));
                let _ = r;
            }
            req(&s, "textDocument/semanticTokens/full", json!({"textDocument": {"uri": URI}}));
            req(&s, "textDocument/documentSymbol", json!({"textDocument": {"uri": URI}}));
            req(&s, "textDocument/formatting", json!({"textDocument": {"uri": URI}, "options": {"tabSize": 4, "insertSpaces": true}}));
        }
    }
}

#[test]
fn formatting_edits_only_the_lines_that_change() {
    let t = "# header\nmodel m\ncoordinate q:angle\nparameter m=1 [kg]\nkinetic T = 1/2*m*q'^2\n# footer\n";
    let (s, _) = open(t);
    let e = req(
        &s,
        "textDocument/formatting",
        json!({"textDocument": {"uri": URI}, "options": {"tabSize": 4, "insertSpaces": true}}),
    );
    let e = e.as_array().unwrap();
    assert_eq!(e.len(), 1);
    assert_eq!(e[0]["range"]["start"], json!({"line": 2, "character": 0}));
    assert_eq!(e[0]["range"]["end"], json!({"line": 4, "character": 0}));
    assert_eq!(
        e[0]["newText"],
        "coordinate q : angle\nparameter m = 1 [kg]\n"
    );
}

/// Issue 28: a rename to a name already taken answers an error that says so
/// and where the name is declared.
#[test]
fn rename_to_a_taken_name_says_so() {
    let rename = |text: &str, at: &str, new: &str| {
        let (s, _) = open(text);
        let r = s.request(Request::new(
            RequestId::from(3),
            "textDocument/rename".into(),
            json!({"textDocument": {"uri": URI}, "position": after(text, at), "newName": new}),
        ));
        let e = r.response_result.expect_err("an error");
        // RequestFailed (LSP 3.17)
        assert_eq!(e.code, -32803);
        e.message
    };
    // `let I` -> `m`, a parameter on line 4
    let m = rename(SMALL, "let I", "m");
    assert_eq!(
        m,
        "`m` is already taken: the parameter `m` is declared on line 4; choose another name"
    );
    // a set -> a controller's name (one namespace)
    let t = format!("{SMALL}controller pp {{ place poles [-1, -2] }}\n");
    let m = rename(&t, "set s", "pp");
    assert!(
        m.contains("`pp` is already taken: the set or controller `pp`"),
        "{m}"
    );
    // a model name -> a recorded controller's own name
    let t =
        format!("{SMALL}recorded controller r {{\n    signal ref [rad]\n    u = 2*(ref - q)\n}}\n");
    let m = rename(&t, "parameter l", "ref");
    assert!(
        m.contains("`ref` is already taken: the recorded controller's signal `ref`"),
        "{m}"
    );
}

/// Issue 31 (r04): a line of 20,000 `$` gives 20,000 errors from `check`;
/// the first 1000 are published with their UTF-16 columns, then one note
/// with the count of the others.
#[test]
fn diagnostics_of_a_long_line_are_capped_and_placed() {
    let text = format!("{SMALL}{}\n", "$".repeat(20_000));
    let (_, diags) = open(&text);
    assert_eq!(diags.len(), plantc_lsp::MAX_PUBLISHED + 1);
    let line = SMALL.matches('\n').count();
    for (k, d) in diags.iter().take(plantc_lsp::MAX_PUBLISHED).enumerate() {
        assert_eq!(
            d["range"]["start"],
            json!({"line": line, "character": k}),
            "{d}"
        );
    }
    let last = diags.last().unwrap();
    assert!(
        last["message"]
            .as_str()
            .unwrap()
            .starts_with("19000 more diagnostics not shown"),
        "{last}"
    );
}

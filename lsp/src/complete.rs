//! Completion: names in scope, effects with argument snippets, units and
//! keywords, chosen from the text before the cursor (which may not parse).

use crate::analysis::Analysis;
use lsp_types::{
    CompletionItem, CompletionItemKind, Documentation, InsertTextFormat, MarkupContent, MarkupKind,
};
use plantc_derive::lang::ast::CoordKind;
use plantc_derive::lang::check::SymbolKind;
use plantc_derive::lang::check::BUILTINS;
use plantc_derive::lang::effects::{self, Effect, EffectKind};
use plantc_derive::lang::lexer::{lex, Tok};
use plantc_derive::lang::parser::KEYWORDS;
use plantc_derive::lang::units::UNITS;

/// Statement templates: keyword, snippet, description.
const STATEMENTS: &[(&str, &str, &str)] = &[
    (
        "model",
        "model ${1:name} \"${2:description}\"",
        "the model's name and title",
    ),
    (
        "coordinate",
        "coordinate ${1:q} : ${2|angle,length|} \"${3:description}\"",
        "a generalised coordinate",
    ),
    (
        "input",
        "input ${1:u} [${2:V}] limits [${3:-10}, ${4:10}] \"${5:description}\"",
        "a control input",
    ),
    (
        "output",
        "output ${1:q}",
        "an output: a coordinate, a let, or `name = expression`",
    ),
    (
        "parameter",
        "parameter ${1:name} = ${2:1} [${3:kg}] \"${4:description}\"",
        "a parameter with value, unit and description",
    ),
    (
        "let",
        "let ${1:name} = ${2:expression}",
        "an intermediate definition",
    ),
    (
        "kinetic",
        "kinetic T = ${1:1/2*m*x'^2}",
        "the kinetic energy",
    ),
    (
        "potential",
        "potential V = ${1:m*g*l*cos(q)}",
        "the potential energy",
    ),
    (
        "force",
        "force ${1:q} = ${2:u}",
        "the generalised force on a coordinate",
    ),
    (
        "sensor",
        "sensor ${1:q} = sensor_offset(${2:d})",
        "a measurement effect",
    ),
    (
        "actuator",
        "actuator ${1:u} = ${2|input_offset,input_delay,deadzone,saturation|}(${3:p})",
        "an input effect",
    ),
    (
        "inertia",
        "inertia ${1:q} = added_inertia(${2:J})",
        "an added inertia on a coordinate (a kinetic-energy term)",
    ),
    (
        "set",
        "set ${1:name} \"${2:description}\" {\n    $0\n}",
        "alternative parameter values",
    ),
    (
        "controller",
        "controller ${1:name} \"${2:description}\" {\n    $0\n}",
        "a controller",
    ),
];

/// Controller statement templates.
const CONTROLLER: &[(&str, &str, &str)] = &[
    (
        "place",
        "place poles [${1:-1, -2, -3, -4}]",
        "pole placement",
    ),
    (
        "lqr",
        "lqr Q [${1:1, 1, 1, 1}] R [${2:1}]",
        "LQR with diagonal weights",
    ),
    (
        "gains",
        "gains K [${1:gains}]",
        "a given state-feedback gain u = -K x",
    ),
    (
        "linearize",
        "linearize output ${1:y}",
        "feedback linearization of an output",
    ),
    (
        "gain",
        "gain ${1:name} = ${2:1}",
        "a named constant for the law",
    ),
    (
        "v",
        "v = ${1:-wn^2*y - 2*zeta*wn*y'}",
        "the outer law (y'' = v)",
    ),
];

fn item(label: &str, kind: CompletionItemKind, detail: &str) -> CompletionItem {
    CompletionItem {
        label: label.to_string(),
        kind: Some(kind),
        detail: (!detail.is_empty()).then(|| detail.to_string()),
        ..Default::default()
    }
}

fn snippet(label: &str, kind: CompletionItemKind, body: &str, detail: &str) -> CompletionItem {
    CompletionItem {
        insert_text: Some(body.to_string()),
        insert_text_format: Some(InsertTextFormat::SNIPPET),
        ..item(label, kind, detail)
    }
}

fn effect_item(e: &Effect) -> CompletionItem {
    let args: Vec<String> = e
        .params
        .iter()
        .enumerate()
        .map(|(i, p)| format!("${{{}:{p}}}", i + 1))
        .collect();
    CompletionItem {
        documentation: Some(Documentation::MarkupContent(MarkupContent {
            kind: MarkupKind::Markdown,
            value: e.doc.to_string(),
        })),
        ..snippet(
            e.name,
            CompletionItemKind::FUNCTION,
            &format!("{}({})", e.name, args.join(", ")),
            &e.signature(),
        )
    }
}

fn names(a: &Analysis, keep: impl Fn(SymbolKind) -> bool) -> Vec<CompletionItem> {
    a.model_names()
        .into_iter()
        .filter(|(_, k)| keep(*k))
        .map(|(n, k)| {
            let (kind, detail) = match k {
                SymbolKind::Coordinate(CoordKind::Angle) => {
                    (CompletionItemKind::VARIABLE, "coordinate (angle)")
                }
                SymbolKind::Coordinate(CoordKind::Length) => {
                    (CompletionItemKind::VARIABLE, "coordinate (length)")
                }
                SymbolKind::Input => (CompletionItemKind::VARIABLE, "input"),
                SymbolKind::Parameter => (CompletionItemKind::CONSTANT, "parameter"),
                SymbolKind::Let => (CompletionItemKind::VARIABLE, "let"),
                SymbolKind::Output => (CompletionItemKind::VARIABLE, "output"),
                SymbolKind::Energy => (CompletionItemKind::VARIABLE, "energy"),
            };
            item(&n, kind, detail)
        })
        .collect()
}

fn builtins() -> Vec<CompletionItem> {
    let mut v: Vec<CompletionItem> = BUILTINS
        .iter()
        .map(|(n, k)| {
            let args = if *k == 2 { "${1:y}, ${2:x}" } else { "${1:x}" };
            snippet(
                n,
                CompletionItemKind::FUNCTION,
                &format!("{n}({args})"),
                "built-in function",
            )
        })
        .collect();
    v.push(item("pi", CompletionItemKind::CONSTANT, "3.14159..."));
    v
}

fn expression(a: &Analysis) -> Vec<CompletionItem> {
    let mut v = names(a, |_| true);
    v.extend(builtins());
    v
}

/// The line that starts the statement the cursor is in: the nearest line at or
/// above `line_start` whose first word is a keyword, or any line in a block.
fn statement_head(text: &str, line_start: usize, in_block: bool) -> &str {
    let mut ls = line_start;
    loop {
        let le = text[ls..].find('\n').map_or(text.len(), |i| ls + i);
        let t = text[ls..le].trim_start();
        let first: String = t
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
            .collect();
        let starts_statement = !first.is_empty()
            && (KEYWORDS.contains(&first.as_str()) || (in_block && !t.starts_with(['+', '-'])));
        if starts_statement || ls == 0 {
            return t;
        }
        ls = text[..ls - 1].rfind('\n').map_or(0, |i| i + 1);
    }
}

/// The keyword of the block (`set` or `controller`) the offset is in, if any.
fn block_at(text: &str, offset: usize) -> Option<String> {
    let mut d = Vec::new();
    let toks = lex(&text[..offset], &mut d);
    let mut stack: Vec<usize> = Vec::new();
    for (i, t) in toks.iter().enumerate() {
        match t.tok {
            Tok::LBrace => stack.push(i),
            Tok::RBrace => {
                stack.pop();
            }
            _ => {}
        }
    }
    let open = *stack.last()?;
    // the header's keyword: first token of the line of `{`
    let line_start = text[..toks[open].span.start]
        .rfind('\n')
        .map_or(0, |i| i + 1);
    let head = text[line_start..].trim_start();
    Some(
        head.split(|c: char| !c.is_ascii_alphanumeric() && c != '_')
            .next()?
            .to_string(),
    )
}

/// Completion items at byte `offset`.
pub fn completion(a: &Analysis, offset: usize) -> Vec<CompletionItem> {
    let text = a.text();
    let offset = offset.min(text.len());
    let line_start = text[..offset].rfind('\n').map_or(0, |i| i + 1);
    let before = &text[line_start..offset];
    if before.contains('#') {
        return Vec::new();
    }
    let word_len = before
        .chars()
        .rev()
        .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
        .count();
    let head_of_line = before[..before.len() - word_len].trim();
    // units: inside `[` after a number, or after an input's name
    if let Some(open) = before.rfind('[') {
        if !before[open..].contains(']') {
            let lead = before[..open].trim_end();
            let words: Vec<&str> = lead.split_whitespace().collect();
            let after_number = lead.ends_with(|c: char| c.is_ascii_digit() || c == '.');
            let input_unit = words.len() == 2 && words[0] == "input";
            if after_number || input_unit {
                return UNITS
                    .iter()
                    .map(|u| item(u.name, CompletionItemKind::UNIT, u.doc))
                    .collect();
            }
            return expression(a);
        }
    }
    let block = block_at(text, offset);
    if head_of_line.is_empty() {
        return match block.as_deref() {
            Some("controller") => CONTROLLER
                .iter()
                .map(|(k, s, d)| snippet(k, CompletionItemKind::KEYWORD, s, d))
                .collect(),
            Some(_) => names(a, |k| k == SymbolKind::Parameter)
                .into_iter()
                .map(|mut i| {
                    i.insert_text = Some(format!("{} = ${{1:value}}", i.label));
                    i.insert_text_format = Some(InsertTextFormat::SNIPPET);
                    i
                })
                .collect(),
            None => STATEMENTS
                .iter()
                .map(|(k, s, d)| snippet(k, CompletionItemKind::KEYWORD, s, d))
                .collect(),
        };
    }
    let head = statement_head(text, line_start, block.is_some());
    let kw: &str = head
        .split(|c: char| !c.is_ascii_alphanumeric() && c != '_')
        .next()
        .unwrap_or("");
    let has_eq = head_of_line.contains('=') || !head.starts_with(before.trim_start());
    let coordinates = |a: &Analysis| names(a, |k| matches!(k, SymbolKind::Coordinate(_)));
    match (block.as_deref(), kw) {
        (None, "coordinate") if before.contains(':') => vec![
            item("angle", CompletionItemKind::ENUM_MEMBER, "unit rad"),
            item("length", CompletionItemKind::ENUM_MEMBER, "unit m"),
        ],
        (None, "force") if has_eq => {
            let mut v: Vec<CompletionItem> = effects::of_kind(EffectKind::Force)
                .map(effect_item)
                .collect();
            v.extend(expression(a));
            v
        }
        (None, "force") => coordinates(a),
        (None, "sensor" | "inertia") if !has_eq => coordinates(a),
        (None, "actuator") if !has_eq => names(a, |k| k == SymbolKind::Input),
        (None, "sensor" | "actuator" | "inertia") => {
            let kind = match kw {
                "sensor" => EffectKind::Sensor,
                "inertia" => EffectKind::Inertia,
                _ => EffectKind::Actuator,
            };
            let mut v: Vec<CompletionItem> = effects::of_kind(kind).map(effect_item).collect();
            v.extend(names(a, |k| k == SymbolKind::Parameter));
            v
        }
        (None, "output") if !has_eq => names(a, |k| {
            matches!(k, SymbolKind::Coordinate(_) | SymbolKind::Let)
        }),
        (None, "parameter" | "input" | "model" | "coordinate") => Vec::new(),
        (Some("controller"), "linearize") => {
            let mut v: Vec<CompletionItem> = a
                .file
                .outputs
                .iter()
                .map(|o| item(&o.name.name, CompletionItemKind::VARIABLE, "output"))
                .collect();
            if !before.contains("output") {
                v = vec![item("output", CompletionItemKind::KEYWORD, "")];
            }
            v
        }
        (Some("controller"), _) => {
            // the law: gains of this controller, y, coordinates, parameters
            let mut v: Vec<CompletionItem> = Vec::new();
            if let Some(c) = a
                .file
                .controllers
                .iter()
                .find(|c| c.span.start <= offset && offset <= c.span.end)
            {
                for st in &c.body {
                    if let plantc_derive::lang::ast::ControllerStmt::Gain { name, .. } = st {
                        v.push(item(&name.name, CompletionItemKind::CONSTANT, "gain"));
                    }
                }
            }
            v.push(item(
                "y",
                CompletionItemKind::VARIABLE,
                "the linearized output",
            ));
            v.extend(names(a, |k| {
                matches!(k, SymbolKind::Coordinate(_) | SymbolKind::Parameter)
            }));
            v.extend(builtins());
            v
        }
        (Some(_), _) => {
            let mut v = names(a, |k| k == SymbolKind::Parameter);
            v.extend(builtins());
            v
        }
        _ => expression(a),
    }
}

//! End to end: the real `plantc lsp` binary driven over stdio with
//! Content-Length framed JSON-RPC, as an editor does.

use serde_json::{json, Value};
use std::io::{BufRead, BufReader, Write};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::{channel, Receiver};
use std::time::Duration;

struct Client {
    child: Child,
    stdin: ChildStdin,
    rx: Receiver<Value>,
    next_id: i64,
    /// Messages received while waiting for something else.
    inbox: Vec<Value>,
}

fn read_message(r: &mut impl BufRead) -> Option<Value> {
    let mut len = None;
    loop {
        let mut line = String::new();
        if r.read_line(&mut line).ok()? == 0 {
            return None;
        }
        let line = line.trim_end();
        if line.is_empty() {
            break;
        }
        if let Some(v) = line.strip_prefix("Content-Length: ") {
            len = v.parse::<usize>().ok();
        }
    }
    let mut buf = vec![0; len?];
    r.read_exact(&mut buf).ok()?;
    serde_json::from_slice(&buf).ok()
}

impl Client {
    fn start() -> Client {
        let mut child = Command::new(env!("CARGO_BIN_EXE_plantc"))
            .arg("lsp")
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("start plantc lsp");
        let stdin = child.stdin.take().unwrap();
        let mut stdout = BufReader::new(child.stdout.take().unwrap());
        let (tx, rx) = channel();
        std::thread::spawn(move || {
            while let Some(m) = read_message(&mut stdout) {
                if tx.send(m).is_err() {
                    break;
                }
            }
        });
        Client {
            child,
            stdin,
            rx,
            next_id: 1,
            inbox: Vec::new(),
        }
    }

    fn send(&mut self, v: Value) {
        let body = serde_json::to_string(&v).unwrap();
        write!(self.stdin, "Content-Length: {}\r\n\r\n{body}", body.len()).unwrap();
        self.stdin.flush().unwrap();
    }

    fn wait(&mut self, pred: impl Fn(&Value) -> bool) -> Value {
        if let Some(i) = self.inbox.iter().position(&pred) {
            return self.inbox.remove(i);
        }
        loop {
            let m = self
                .rx
                .recv_timeout(Duration::from_secs(20))
                .expect("no reply from the server within 20 s");
            if pred(&m) {
                return m;
            }
            self.inbox.push(m);
        }
    }

    /// Sends a request and returns its reply (`result` or the whole error reply).
    fn request(&mut self, method: &str, params: Value) -> Value {
        let id = self.next_id;
        self.next_id += 1;
        self.send(json!({"jsonrpc": "2.0", "id": id, "method": method, "params": params}));
        self.wait(|m| m["id"] == json!(id))
    }

    fn notify(&mut self, method: &str, params: Value) {
        self.send(json!({"jsonrpc": "2.0", "method": method, "params": params}));
    }

    fn diagnostics(&mut self, version: i64) -> Vec<Value> {
        let m = self.wait(|m| {
            m["method"] == "textDocument/publishDiagnostics" && m["params"]["version"] == version
        });
        m["params"]["diagnostics"].as_array().unwrap().clone()
    }
}

const URI: &str = "file:///work/rotary_pendulum.plant";

/// LSP position (line, UTF-16 column) of the `nth` occurrence of `needle`.
fn pos(text: &str, needle: &str, nth: usize) -> Value {
    let at = text
        .match_indices(needle)
        .nth(nth)
        .unwrap_or_else(|| panic!("`{needle}` #{nth} not in the text"))
        .0;
    let line_start = text[..at].rfind('\n').map_or(0, |i| i + 1);
    let line = text[..at].matches('\n').count();
    let col = text[line_start..at].encode_utf16().count();
    json!({"line": line, "character": col})
}

fn tdp(text: &str, needle: &str, nth: usize) -> Value {
    json!({"textDocument": {"uri": URI}, "position": pos(text, needle, nth)})
}

/// Applies LSP text edits (ranges in the original text) to `text`.
fn apply_edits(text: &str, edits: &[Value]) -> String {
    let offset = |p: &Value| {
        let line = p["line"].as_u64().unwrap() as usize;
        let ch = p["character"].as_u64().unwrap() as usize;
        let start: usize = text.split_inclusive('\n').take(line).map(str::len).sum();
        let mut units = 0;
        for (i, c) in text[start..].char_indices() {
            if units >= ch || c == '\n' {
                return start + i;
            }
            units += c.len_utf16();
        }
        text.len()
    };
    let mut e: Vec<(usize, usize, String)> = edits
        .iter()
        .map(|x| {
            (
                offset(&x["range"]["start"]),
                offset(&x["range"]["end"]),
                x["newText"].as_str().unwrap().to_string(),
            )
        })
        .collect();
    e.sort_by_key(|x| std::cmp::Reverse(x.0));
    let mut out = text.to_string();
    for (s, en, t) in e {
        out.replace_range(s..en, &t);
    }
    out
}

/// Occurrences of `word` as a whole word in code (not in comments or strings).
fn count_word(text: &str, word: &str) -> usize {
    text.lines()
        .map(|l| {
            let code = l.split('#').next().unwrap();
            let mut n = 0;
            let mut in_str = false;
            let b = code.as_bytes();
            let is_w = |c: u8| c.is_ascii_alphanumeric() || c == b'_';
            for i in 0..b.len() {
                if b[i] == b'"' {
                    in_str = !in_str;
                }
                if !in_str
                    && code[i..].starts_with(word)
                    && (i == 0 || !is_w(b[i - 1]))
                    && b.get(i + word.len()).is_none_or(|c| !is_w(*c))
                {
                    n += 1;
                }
            }
            n
        })
        .sum()
}

/// Sends one incremental change and applies it to the client's copy.
fn edit(c: &mut Client, text: &mut String, version: i64, start: Value, end: Value, new: &str) {
    let change = json!({"range": {"start": start, "end": end}, "text": new});
    let edits = [json!({"range": change["range"], "newText": new})];
    *text = apply_edits(text, &edits);
    c.notify(
        "textDocument/didChange",
        json!({"textDocument": {"uri": URI, "version": version}, "contentChanges": [change]}),
    );
}

fn hover_text(reply: &Value) -> String {
    reply["result"]["contents"]["value"]
        .as_str()
        .unwrap_or_else(|| panic!("no hover: {reply}"))
        .to_string()
}

#[test]
fn plantc_lsp_over_stdio() {
    let model = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../models/rotary_pendulum.plant"
    ))
    .unwrap();
    let mut c = Client::start();

    let init = c.request(
        "initialize",
        json!({"processId": null, "rootUri": null, "capabilities": {}}),
    );
    let caps = &init["result"]["capabilities"];
    assert_eq!(caps["textDocumentSync"], 2, "incremental sync: {caps}");
    assert_eq!(caps["positionEncoding"], "utf-16");
    assert_eq!(caps["renameProvider"]["prepareProvider"], true);
    c.notify("initialized", json!({}));

    // open: the reference model checks clean
    c.notify(
        "textDocument/didOpen",
        json!({"textDocument": {"uri": URI, "languageId": "plant", "version": 1, "text": model}}),
    );
    let d = c.diagnostics(1);
    assert!(d.iter().all(|d| d["severity"] != 1), "{d:?}");

    // change 1 (incremental, after a non-ASCII character on the same line):
    // the doc string of J1 gets a Greek letter, then its upper bound changes
    let mut text = model.clone();
    let doc = "\"arm inertia about its centre of mass\"";
    let at = pos(&text, doc, 0);
    let inside = json!({"line": at["line"], "character": at["character"].as_u64().unwrap() + 1});
    edit(&mut c, &mut text, 2, inside.clone(), inside, "ρ·J1: ");
    let hi = pos(&text, "1e-2]", 0);
    let hi_end = json!({"line": hi["line"], "character": hi["character"].as_u64().unwrap() + 4});
    edit(&mut c, &mut text, 3, hi, hi_end, "2e-2");
    assert!(text.contains("\"ρ·J1: arm inertia about its centre of mass\""));
    assert!(text.contains("estimate [1e-5, 2e-2]"));
    assert!(c.diagnostics(2).iter().all(|d| d["severity"] != 1));
    assert!(c.diagnostics(3).iter().all(|d| d["severity"] != 1));

    // change 2 introduces an error: a misspelt parameter
    let b2 = pos(&text, "viscous_friction(b2)", 0);
    let start = json!({"line": b2["line"], "character": b2["character"].as_u64().unwrap() + 17});
    let end = json!({"line": b2["line"], "character": b2["character"].as_u64().unwrap() + 19});
    edit(&mut c, &mut text, 4, start.clone(), end, "bb2");
    let d = c.diagnostics(4);
    let err = d
        .iter()
        .find(|d| d["severity"] == 1)
        .unwrap_or_else(|| panic!("no error after the change: {d:?}"));
    assert_eq!(err["message"], "unknown name `bb2`");
    assert_eq!(err["code"], "plantc::unknown_name");
    assert_eq!(err["range"]["start"], start);
    // the quick fix named by the help
    let actions = c.request(
        "textDocument/codeAction",
        json!({"textDocument": {"uri": URI}, "range": err["range"], "context": {"diagnostics": [err]}}),
    );
    let fix = &actions["result"][0];
    assert_eq!(fix["title"], "Replace `bb2` with `b2`", "{actions}");
    let fix_edits = fix["edit"]["changes"][URI].as_array().unwrap().clone();
    // change 3 applies it: the error is gone
    let r = &fix_edits[0]["range"];
    edit(
        &mut c,
        &mut text,
        5,
        r["start"].clone(),
        r["end"].clone(),
        "b2",
    );
    assert!(c.diagnostics(5).iter().all(|d| d["severity"] != 1));
    assert!(text.contains("force alpha = viscous_friction(b2)"));

    // hover: a parameter (value, unit, description, bounds as changed above)
    let h = hover_text(&c.request("textDocument/hover", tdp(&text, "J1 + m1", 0)));
    for part in [
        "parameter J1 = 9.98e-4 [kg*m^2]",
        "ρ·J1: arm inertia",
        "[1e-5, 2e-2]",
    ] {
        assert!(h.contains(part), "`{part}` not in hover: {h}");
    }
    // a let: its expression and derived unit; an effect; a coordinate
    let h = hover_text(&c.request("textDocument/hover", tdp(&text, "J0h + J2h", 0)));
    assert!(
        h.contains("let J0h = J1 + m1*l1^2 + m2*L1^2") && h.contains("`kg*m^2`"),
        "{h}"
    );
    let h = hover_text(&c.request("textDocument/hover", tdp(&text, "coulomb_friction(Fg1)", 0)));
    assert!(
        h.contains("coulomb_friction(Fc)") && h.contains("`Fc` = `Fg1`"),
        "{h}"
    );
    let h = hover_text(&c.request("textDocument/hover", tdp(&text, "alpha)^2", 0)));
    assert!(
        h.contains("coordinate alpha : angle") && h.contains("rad"),
        "{h}"
    );

    // definition of J0h used in T: the `let` line
    let def = c.request("textDocument/definition", tdp(&text, "J0h + J2h", 0));
    assert_eq!(def["result"]["range"]["start"], pos(&text, "J0h =", 0));

    // references of m2: the declaration and every use
    let refs = c.request(
        "textDocument/references",
        json!({"textDocument": {"uri": URI}, "position": pos(&text, "m2*g", 0),
               "context": {"includeDeclaration": true}}),
    );
    assert_eq!(
        refs["result"].as_array().unwrap().len(),
        count_word(&text, "m2")
    );

    // rename J2h -> J_pend through the lossless editor
    let ren = c.request(
        "textDocument/rename",
        json!({"textDocument": {"uri": URI}, "position": pos(&text, "J2h*sin", 0), "newName": "J_pend"}),
    );
    let edits = ren["result"]["changes"][URI].as_array().unwrap();
    assert_eq!(edits.len(), count_word(&text, "J2h"));
    let renamed = apply_edits(&text, edits);
    assert_eq!(count_word(&renamed, "J2h"), 0);
    assert_eq!(
        renamed.replace("J_pend", "J2h"),
        text,
        "only the name changed"
    );
    // a taken name is refused
    let taken = c.request(
        "textDocument/rename",
        json!({"textDocument": {"uri": URI}, "position": pos(&text, "J2h*sin", 0), "newName": "m1"}),
    );
    assert!(
        taken["error"]["message"].as_str().unwrap().contains("`m1`"),
        "{taken}"
    );

    // completion in a force line: effects with snippets, names in scope
    let after = pos(&text, "viscous_friction(b2)", 0);
    let end =
        json!({"line": after["line"], "character": after["character"].as_u64().unwrap() + 20});
    let comp = c.request(
        "textDocument/completion",
        json!({"textDocument": {"uri": URI}, "position": end}),
    );
    let items = comp["result"].as_array().unwrap();
    let find = |l: &str| items.iter().find(|i| i["label"] == l).cloned();
    let coulomb = find("coulomb_friction").expect("effect completion");
    assert_eq!(coulomb["insertText"], "coulomb_friction(${1:Fc})");
    assert_eq!(coulomb["insertTextFormat"], 2);
    assert!(find("b2").is_some() && find("sin").is_some());

    // inlay hints: derived units of lets, T, V, forces
    let hints = c.request(
        "textDocument/inlayHint",
        json!({"textDocument": {"uri": URI}, "range": {"start": {"line": 0, "character": 0},
               "end": {"line": 10000, "character": 0}}}),
    );
    let labels: Vec<&str> = hints["result"]
        .as_array()
        .unwrap()
        .iter()
        .map(|h| h["label"].as_str().unwrap())
        .collect();
    assert_eq!(
        labels.iter().filter(|l| **l == ": [kg*m^2]").count(),
        3,
        "{labels:?}"
    );
    assert!(
        labels.iter().filter(|l| **l == ": [N*m]").count() >= 4,
        "{labels:?}"
    );

    // outline and semantic tokens
    let syms = c.request(
        "textDocument/documentSymbol",
        json!({"textDocument": {"uri": URI}}),
    );
    let names: Vec<&str> = syms["result"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["name"].as_str().unwrap())
        .collect();
    assert!(
        names.contains(&"pole_placement") && names.contains(&"J1"),
        "{names:?}"
    );
    let toks = c.request(
        "textDocument/semanticTokens/full",
        json!({"textDocument": {"uri": URI}}),
    );
    assert!(toks["result"]["data"].as_array().unwrap().len() > 5 * 100);

    // formatting: plantc fmt's layout
    let fmt = c.request(
        "textDocument/formatting",
        json!({"textDocument": {"uri": URI}, "options": {"tabSize": 4, "insertSpaces": true}}),
    );
    let formatted = apply_edits(&text, fmt["result"].as_array().unwrap());
    assert_eq!(
        formatted,
        plantc_derive::lang::format::format(&text).unwrap()
    );
    assert_ne!(formatted, text);

    // shutdown and exit
    let bye = c.request("shutdown", Value::Null);
    assert!(bye["error"].is_null(), "{bye}");
    c.notify("exit", Value::Null);
    let deadline = std::time::Instant::now() + Duration::from_secs(20);
    loop {
        if let Some(status) = c.child.try_wait().unwrap() {
            assert!(status.success(), "{status}");
            break;
        }
        assert!(
            std::time::Instant::now() < deadline,
            "the server did not exit"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Issue 31 (r05, r14): malformed frames, batches, odd ids, a huge
/// Content-Length and an unusable didChange each get an answer (an error
/// reply or a message) and the server goes on; `exit` without `shutdown`
/// ends with code 1.
#[test]
fn no_frame_ends_the_server() {
    let mut c = Client::start();
    c.request("initialize", json!({"capabilities": {}}));
    c.notify("initialized", json!({}));
    let raw = |c: &mut Client, bytes: &[u8]| {
        c.stdin.write_all(bytes).unwrap();
        c.stdin.flush().unwrap();
    };
    let frame = |body: &str| format!("Content-Length: {}\r\n\r\n{body}", body.len()).into_bytes();
    for (body, code, id) in [
        (r#"{"jsonrpc": "2.0", "id": 9, "#, -32700, Value::Null),
        (
            r#"[{"jsonrpc":"2.0","id":9,"method":"x"}]"#,
            -32600,
            Value::Null,
        ),
        (r#"{"jsonrpc":"2.0","id":9,"method":7}"#, -32600, json!(9)),
        (
            r#"{"jsonrpc":"2.0","method":"x","params":"\ud83d"}"#,
            -32700,
            Value::Null,
        ),
        (
            r#"{"jsonrpc":"2.0","id":3000000000,"method":"textDocument/hover"}"#,
            -32600,
            json!(3000000000u64),
        ),
        (
            r#"{"jsonrpc":"2.0","id":1.5,"method":"textDocument/hover"}"#,
            -32600,
            json!(1.5),
        ),
    ] {
        raw(&mut c, &frame(body));
        let r = c.wait(|m| m.get("error").is_some());
        assert_eq!(r["error"]["code"], json!(code), "{body}: {r}");
        assert_eq!(r["id"], id, "{body}: {r}");
    }
    // announced lengths the server will not allocate: refused once read
    raw(&mut c, b"Content-Length: 18446744073709551616\r\n\r\n");
    let r = c.wait(|m| m.get("error").is_some());
    assert_eq!(r["error"]["code"], json!(-32700), "{r}");
    let mut big = b"Content-Length: 67108865\r\n\r\n".to_vec();
    big.resize(big.len() + 67_108_865, b' ');
    raw(&mut c, &big);
    let r = c.wait(|m| m.get("error").is_some());
    assert!(
        r["error"]["message"].as_str().unwrap().contains("67108865"),
        "{r}"
    );
    // a change the server cannot apply is said, not dropped silently
    c.notify(
        "textDocument/didOpen",
        json!({"textDocument": {"uri": URI, "languageId": "plant", "version": 1, "text": "model m\n"}}),
    );
    c.diagnostics(1);
    c.notify(
        "textDocument/didChange",
        json!({"textDocument": {"uri": URI, "version": 2}, "contentChanges": [
            {"range": {"start": {"line": 0, "character": 4294967296u64},
                       "end": {"line": 0, "character": 4294967296u64}}, "text": "x"}]}),
    );
    let m = c.wait(|m| m["method"] == "window/showMessage");
    assert!(
        m["params"]["message"].as_str().unwrap().contains("reopen"),
        "{m}"
    );
    // still answering
    let r = c.request(
        "textDocument/hover",
        json!({"textDocument": {"uri": URI}, "position": {"line": 0, "character": 1}}),
    );
    assert!(r.get("result").is_some(), "{r}");
    c.notify("exit", Value::Null);
    let status = c.child.wait().unwrap();
    assert_eq!(status.code(), Some(1), "exit without shutdown");
}

/// Issue 31 (r05): a Content-Length beyond the server's limit is answered as
/// soon as its header is read, before any byte of the body (a client that
/// announced 2^64 - 1 bytes would otherwise wait for ever); the body, when
/// it comes, is skipped and the next frame answered.
#[test]
fn a_refused_length_is_answered_before_its_body() {
    let mut c = Client::start();
    c.request("initialize", json!({"capabilities": {}}));
    c.notify("initialized", json!({}));
    // 64 MiB + 1: one byte over the limit (transport::MAX_CONTENT_LENGTH)
    let n = (64u64 << 20) + 1;
    write!(c.stdin, "Content-Length: {n}\r\n\r\n").unwrap();
    c.stdin.flush().unwrap();
    let r = c.wait(|m| m.get("error").is_some());
    assert_eq!(r["error"]["code"], json!(-32600), "{r}");
    assert!(
        r["error"]["message"]
            .as_str()
            .unwrap()
            .contains(&n.to_string()),
        "{r}"
    );
    c.stdin.write_all(&vec![b' '; n as usize]).unwrap();
    let r = c.request("shutdown", Value::Null);
    assert!(r["error"].is_null(), "{r}");
    c.notify("exit", Value::Null);
    assert_eq!(c.child.wait().unwrap().code(), Some(0));
    // 2^64 - 1: answered at once too; the server then skips what comes
    let mut c = Client::start();
    c.request("initialize", json!({"capabilities": {}}));
    c.notify("initialized", json!({}));
    c.stdin
        .write_all(b"Content-Length: 18446744073709551615\r\n\r\n")
        .unwrap();
    c.stdin.flush().unwrap();
    let r = c.wait(|m| m.get("error").is_some());
    assert_eq!(r["error"]["code"], json!(-32600), "{r}");
    c.child.kill().unwrap();
    c.child.wait().unwrap();
}

/// A request sent between `initialize` and `initialized` is answered; the
/// session goes on (it used to end with "expected initialized notification").
#[test]
fn a_request_before_initialized_is_answered() {
    let mut c = Client::start();
    c.request("initialize", json!({"capabilities": {}}));
    let r = c.request(
        "textDocument/hover",
        json!({"textDocument": {"uri": URI}, "position": {"line": 0, "character": 0}}),
    );
    assert!(r.get("id").is_some(), "{r}");
    c.notify("initialized", json!({}));
    let bye = c.request("shutdown", Value::Null);
    assert!(bye["error"].is_null(), "{bye}");
    c.notify("exit", Value::Null);
    assert_eq!(c.child.wait().unwrap().code(), Some(0));
}

//! Every malformed fixture of `plantc-derive`'s check tests gives, through
//! the server, the diagnostics `check` gives: same messages, same spans.

use lsp_server::{Connection, Message, Notification, Request, RequestId};
use lsp_types::{Position, PublishDiagnosticsParams};
use plantc_derive::lang::parse_and_check;
use plantc_lsp::Document;
use serde_json::json;
use std::time::Duration;

fn start() -> (Connection, std::thread::JoinHandle<()>) {
    let (server, client) = Connection::memory();
    let h = std::thread::spawn(move || plantc_lsp::serve(&server).unwrap());
    client
        .sender
        .send(Message::Request(Request::new(
            RequestId::from(1),
            "initialize".into(),
            json!({"capabilities": {}}),
        )))
        .unwrap();
    let _ = client
        .receiver
        .recv_timeout(Duration::from_secs(10))
        .unwrap();
    client
        .sender
        .send(Message::Notification(Notification::new(
            "initialized".into(),
            json!({}),
        )))
        .unwrap();
    (client, h)
}

fn stop(client: Connection, h: std::thread::JoinHandle<()>) {
    client
        .sender
        .send(Message::Request(Request::new(
            RequestId::from(2),
            "shutdown".into(),
            json!(null),
        )))
        .unwrap();
    let _ = client
        .receiver
        .recv_timeout(Duration::from_secs(10))
        .unwrap();
    client
        .sender
        .send(Message::Notification(Notification::new(
            "exit".into(),
            json!(null),
        )))
        .unwrap();
    h.join().unwrap();
}

#[test]
fn malformed_fixtures_give_checks_diagnostics() {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../derive/tests/malformed");
    let mut files: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "plant"))
        .collect();
    files.sort();
    assert!(files.len() >= 18, "fixtures not found in {dir}");
    let (client, h) = start();
    let mut compared = 0;
    for (i, path) in files.iter().enumerate() {
        let text = std::fs::read_to_string(path).unwrap();
        let name = path.file_name().unwrap().to_str().unwrap();
        let uri = format!("file:///fixtures/{name}");
        client
            .sender
            .send(Message::Notification(Notification::new(
                "textDocument/didOpen".into(),
                json!({"textDocument": {"uri": uri, "languageId": "plant", "version": i, "text": text}}),
            )))
            .unwrap();
        let got = loop {
            let m = client
                .receiver
                .recv_timeout(Duration::from_secs(10))
                .unwrap();
            if let Message::Notification(n) = m {
                let p: PublishDiagnosticsParams = serde_json::from_value(n.params).unwrap();
                if p.uri.as_str() == uri {
                    break p.diagnostics;
                }
            }
        };
        let want = parse_and_check(name, &text).diagnostics;
        assert!(
            want.iter().any(|d| d.is_error()),
            "{name}: no error to compare"
        );
        assert_eq!(got.len(), want.len(), "{name}: number of diagnostics");
        // positions computed independently of the server: line and UTF-16 column
        let doc = Document::new(text.clone(), 0);
        let lc = |off: usize| {
            let line = text[..off].matches('\n').count() as u32;
            let ls = text[..off].rfind('\n').map_or(0, |i| i + 1);
            Position::new(line, text[ls..off].encode_utf16().count() as u32)
        };
        for (g, w) in got.iter().zip(&want) {
            assert_eq!(g.message, w.message, "{name}");
            assert_eq!(g.range.start, lc(w.primary.start), "{name}: {}", w.message);
            assert_eq!(g.range.end, lc(w.primary.end), "{name}: {}", w.message);
            assert_eq!(g.range, doc.range(w.primary));
            assert_eq!(
                g.code,
                Some(lsp_types::NumberOrString::String(w.code.to_string()))
            );
            compared += 1;
        }
    }
    assert!(compared >= files.len());
    stop(client, h);
}

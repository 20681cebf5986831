//! Latency of diagnostics after a change, for the rotary pendulum model:
//! from sending `didChange` (one incremental edit) to receiving the
//! `publishDiagnostics` it causes, through the server loop on an in-memory
//! connection. The budget is 20 ms. Run: `cargo bench -p plantc-lsp`.

use criterion::{criterion_group, criterion_main, Criterion};
use lsp_server::{Connection, Message, Notification, Request, RequestId};
use serde_json::json;
use std::time::Duration;

const MODEL: &str = include_str!("../../models/rotary_pendulum.plant");
const URI: &str = "file:///bench/rotary_pendulum.plant";

fn latency(c: &mut Criterion) {
    let (server, client) = Connection::memory();
    let h = std::thread::spawn(move || plantc_lsp::serve(&server).unwrap());
    let send = |m: Message| client.sender.send(m).unwrap();
    send(Message::Request(Request::new(
        RequestId::from(1),
        "initialize".into(),
        json!({"capabilities": {}}),
    )));
    client.receiver.recv().unwrap();
    send(Message::Notification(Notification::new(
        "initialized".into(),
        json!({}),
    )));
    send(Message::Notification(Notification::new(
        "textDocument/didOpen".into(),
        json!({"textDocument": {"uri": URI, "languageId": "plant", "version": 0, "text": MODEL}}),
    )));
    client.receiver.recv().unwrap();
    // the edit: the value of m1 (`0.257`) alternates between two literals
    let at = MODEL.find("0.257").expect("m1's value");
    let line = MODEL[..at].matches('\n').count();
    let col = at - MODEL[..at].rfind('\n').map_or(0, |i| i + 1);
    let mut version = 0;
    let mut group = c.benchmark_group("lsp");
    group.measurement_time(Duration::from_secs(5));
    group.bench_function("rotary_pendulum didChange -> publishDiagnostics", |b| {
        b.iter(|| {
            version += 1;
            let new = if version % 2 == 0 { "0.257" } else { "0.258" };
            send(Message::Notification(Notification::new(
                "textDocument/didChange".into(),
                json!({"textDocument": {"uri": URI, "version": version},
                       "contentChanges": [{"range": {"start": {"line": line, "character": col},
                       "end": {"line": line, "character": col + 5}}, "text": new}]}),
            )));
            match client.receiver.recv().unwrap() {
                Message::Notification(n) => assert_eq!(n.method, "textDocument/publishDiagnostics"),
                other => panic!("{other:?}"),
            }
        })
    });
    group.finish();
    send(Message::Request(Request::new(
        RequestId::from(2),
        "shutdown".into(),
        json!(null),
    )));
    client.receiver.recv().unwrap();
    send(Message::Notification(Notification::new(
        "exit".into(),
        json!(null),
    )));
    h.join().unwrap();
}

criterion_group!(benches, latency);
criterion_main!(benches);

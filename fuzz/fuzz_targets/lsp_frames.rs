//! A byte stream through the language server's framing and dispatch (issue
//! 31): malformed frames get replies, messages are handled; nothing may
//! panic, abort or allocate beyond the frame limit.
#![no_main]

use libfuzzer_sys::fuzz_target;
use lsp_server::Message;
use plantc_lsp::transport::{read_message, skip_body, Incoming};
use plantc_lsp::State;

fuzz_target!(|data: &[u8]| {
    let mut input = std::io::BufReader::new(data);
    let mut state = State::default();
    // a bound on the messages per input keeps each run short
    for _ in 0..64 {
        match read_message(&mut input) {
            Ok(Some(Incoming::Message(Message::Request(r)))) => {
                let _ = state.request(r);
            }
            Ok(Some(Incoming::Message(Message::Notification(n)))) => {
                let _ = state.notify(n);
            }
            Ok(Some(Incoming::Refused { skip, .. })) => {
                if !matches!(skip_body(&mut input, skip), Ok(true)) {
                    break;
                }
            }
            Ok(Some(_)) => {}
            Ok(None) | Err(_) => break,
        }
    }
});

//! The LSP base protocol over byte streams (`Content-Length` frames of
//! JSON-RPC), bounded and forgiving: no frame, however malformed, ends the
//! server or makes it allocate more than a bounded amount.
//!
//! - A header line longer than [`MAX_HEADER_LINE`] is skipped; lines ending
//!   in `\n` alone are accepted as well as `\r\n`; a `Content-Length` that is
//!   not a number (or overflows) gets a parse error reply, and reading
//!   resumes at the next line naming a `Content-Length`.
//! - A body longer than [`MAX_CONTENT_LENGTH`] is answered with an error at
//!   once, when its header has been read ([`Incoming::Refused`]: a client
//!   that announced 2^64 - 1 bytes learns it before sending any), then read
//!   and dropped as it comes ([`skip_body`]: never allocated), so the next
//!   frame is read in step.
//! - A body that is not JSON (or not UTF-8, or holds a lone surrogate) is
//!   answered with `-32700 Parse error`; a batch, a non-object, a `method`
//!   that is not a string or a request `id` that is neither a 32-bit integer
//!   nor a string (what the server's message types can carry) with
//!   `-32600 Invalid Request`, echoing the id when it is a number or null.
//!
//! [`read_message`] returns what to do with each frame; [`write_frame`]
//! writes one frame whole under the output lock, so replies written by the
//! reading thread and by the server never interleave.

use lsp_server::Message;
use serde_json::{json, Value};
use std::io::{self, BufRead, Read, Write};

/// Longest header line read (bytes). Real headers are under 100 bytes
/// (`Content-Length: N`, `Content-Type: ...`); 8 KiB is far beyond any, and
/// bounds what a line without an end can make the server hold.
pub const MAX_HEADER_LINE: usize = 8 * 1024;

/// Largest message body accepted (bytes): 64 MiB. The server holds an open
/// document several times over (text, tree, tokens); the largest bundled
/// model is 12 KB and a 20-link chain about 50 KB, so 64 MiB is a thousand
/// times any plausible model and still a bounded allocation.
pub const MAX_CONTENT_LENGTH: u64 = 64 << 20;

/// JSON-RPC's parse error code.
pub const PARSE_ERROR: i32 = -32700;
/// JSON-RPC's invalid request code.
pub const INVALID_REQUEST: i32 = -32600;

/// What one frame of the input stream is.
#[derive(Debug)]
pub enum Incoming {
    /// A well-formed message for the server.
    Message(Message),
    /// A malformed frame: this reply (a JSON-RPC error response) goes back
    /// to the client, and reading goes on.
    Reply(Value),
    /// A frame whose body is longer than [`MAX_CONTENT_LENGTH`]: `reply`
    /// goes back to the client now, then [`skip_body`] drops its `skip`
    /// bytes before the next frame is read.
    Refused {
        /// The error response.
        reply: Value,
        /// The announced length of the body, still to be read.
        skip: u64,
    },
}

/// Reads and drops `n` bytes (a refused body) without holding them;
/// `false` when the stream ends first.
pub fn skip_body(r: &mut impl BufRead, n: u64) -> io::Result<bool> {
    Ok(io::copy(&mut r.by_ref().take(n), &mut io::sink())? == n)
}

/// An error response with `id` (null when unknown).
pub fn error_reply(id: Value, code: i32, message: impl Into<String>) -> Value {
    json!({"jsonrpc": "2.0", "id": id, "error": {"code": code, "message": message.into()}})
}

/// Reads one line of at most [`MAX_HEADER_LINE`] bytes (without its line
/// end); `None` at the end of the stream. A longer line is consumed to its
/// end and returned as `Some(Err(()))`.
fn header_line(r: &mut impl BufRead) -> io::Result<Option<Result<String, ()>>> {
    let mut line = Vec::new();
    let n = r
        .by_ref()
        .take(MAX_HEADER_LINE as u64)
        .read_until(b'\n', &mut line)?;
    if n == 0 {
        return Ok(None);
    }
    if line.last() != Some(&b'\n') {
        if n < MAX_HEADER_LINE {
            return Ok(None); // the stream ended inside the line
        }
        // too long: skip to its end without holding it
        let mut skip = Vec::new();
        loop {
            skip.clear();
            let k = r
                .by_ref()
                .take(MAX_HEADER_LINE as u64)
                .read_until(b'\n', &mut skip)?;
            if k == 0 || skip.last() == Some(&b'\n') {
                return Ok(Some(Err(())));
            }
        }
    }
    line.pop();
    if line.last() == Some(&b'\r') {
        line.pop();
    }
    Ok(Some(Ok(String::from_utf8_lossy(&line).into_owned())))
}

/// The value of a `Content-Length` header anywhere in `line` (after garbage
/// left by a broken frame, too): `Some(Ok(n))`, `Some(Err(text))` when the
/// value is not a number that fits, `None` when the line names no length.
fn content_length(line: &str) -> Option<Result<u64, String>> {
    let lower = line.to_ascii_lowercase();
    let at = lower.find("content-length:")?;
    let value = line[at + "content-length:".len()..].trim();
    Some(
        value
            .parse::<u64>()
            .ok()
            .filter(|_| value.bytes().all(|b| b.is_ascii_digit()))
            .ok_or_else(|| value.chars().take(40).collect()),
    )
}

/// Reads the next frame; `Ok(None)` when the stream has ended.
pub fn read_message(r: &mut impl BufRead) -> io::Result<Option<Incoming>> {
    let mut length: Option<u64> = None;
    loop {
        let Some(line) = header_line(r)? else {
            return Ok(None);
        };
        let Ok(line) = line else {
            return Ok(Some(Incoming::Reply(error_reply(
                Value::Null,
                PARSE_ERROR,
                format!("Parse error: a header line longer than {MAX_HEADER_LINE} bytes"),
            ))));
        };
        if line.is_empty() {
            if length.is_some() {
                break;
            }
            continue; // blank lines between frames, or before the first
        }
        match content_length(&line) {
            Some(Ok(n)) => length = Some(n),
            Some(Err(bad)) => {
                return Ok(Some(Incoming::Reply(error_reply(
                    Value::Null,
                    PARSE_ERROR,
                    format!("Parse error: Content-Length `{bad}` is not a byte count"),
                ))))
            }
            None => {} // Content-Type, or garbage before a header
        }
    }
    let length = length.unwrap_or(0);
    if length > MAX_CONTENT_LENGTH {
        return Ok(Some(Incoming::Refused {
            reply: error_reply(
                Value::Null,
                INVALID_REQUEST,
                format!(
                    "message of {length} bytes refused (the limit is {MAX_CONTENT_LENGTH} \
                     bytes); its bytes are skipped"
                ),
            ),
            skip: length,
        }));
    }
    // grows as the bytes come: a length announced but not sent costs nothing
    let mut body = Vec::with_capacity(length.min(1 << 20) as usize);
    r.by_ref().take(length).read_to_end(&mut body)?;
    if (body.len() as u64) < length {
        return Ok(None);
    }
    Ok(Some(decode(&body)))
}

/// A message from a frame's body, or the error reply it deserves.
pub fn decode(body: &[u8]) -> Incoming {
    let value: Value = match serde_json::from_slice(body) {
        Ok(v) => v,
        Err(e) => {
            return Incoming::Reply(error_reply(
                Value::Null,
                PARSE_ERROR,
                format!("Parse error: {e}"),
            ))
        }
    };
    let invalid = |id: Value, why: &str| {
        Incoming::Reply(error_reply(
            id,
            INVALID_REQUEST,
            format!("Invalid Request: {why}"),
        ))
    };
    let Some(obj) = value.as_object() else {
        let why = if value.is_array() {
            "batches are not part of LSP; send one message per frame"
        } else {
            "a message is a JSON object"
        };
        return invalid(Value::Null, why);
    };
    // the id to echo: JSON-RPC ids are numbers, strings or null
    let echo = match obj.get("id") {
        Some(v @ (Value::Number(_) | Value::String(_))) => v.clone(),
        _ => Value::Null,
    };
    let method = obj.get("method");
    if method.is_some_and(|m| !m.is_string()) {
        return invalid(echo, "`method` must be a string");
    }
    if let (Some(_), Some(id)) = (method, obj.get("id")) {
        let fits = match id {
            Value::String(_) => true,
            Value::Number(n) => n.as_i64().is_some_and(|i| i32::try_from(i).is_ok()),
            _ => false,
        };
        if !fits {
            return invalid(
                echo,
                &format!(
                    "request id {id} is not supported: use a string or an integer within 32 bits"
                ),
            );
        }
    }
    match serde_json::from_value::<Message>(value) {
        Ok(m) => Incoming::Message(m),
        Err(e) => invalid(echo, &e.to_string()),
    }
}

/// Writes one frame (`Content-Length` header and body) whole and flushes.
pub fn write_frame(w: &mut impl Write, body: &[u8]) -> io::Result<()> {
    let mut frame = format!("Content-Length: {}\r\n\r\n", body.len()).into_bytes();
    frame.extend_from_slice(body);
    w.write_all(&frame)?;
    w.flush()
}

/// Writes a message as one frame.
pub fn write_message(w: &mut impl Write, m: &Message) -> io::Result<()> {
    let mut buf = Vec::new();
    m.write(&mut buf)?;
    // `Message::write` frames it already: pass the bytes through as they are
    w.write_all(&buf)?;
    w.flush()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frames(input: &[u8]) -> Vec<Incoming> {
        let mut r = io::BufReader::new(input);
        let mut out = Vec::new();
        while let Some(m) = read_message(&mut r).unwrap() {
            let skip = match &m {
                Incoming::Refused { skip, .. } => Some(*skip),
                _ => None,
            };
            out.push(m);
            if let Some(n) = skip {
                if !skip_body(&mut r, n).unwrap() {
                    break;
                }
            }
        }
        out
    }

    fn code(i: &Incoming) -> Option<i64> {
        match i {
            Incoming::Reply(v) | Incoming::Refused { reply: v, .. } => v["error"]["code"].as_i64(),
            Incoming::Message(_) => None,
        }
    }

    fn frame(body: &str) -> Vec<u8> {
        format!("Content-Length: {}\r\n\r\n{body}", body.len()).into_bytes()
    }

    #[test]
    fn malformed_frames_get_replies_and_reading_goes_on() {
        let ok = r#"{"jsonrpc":"2.0","id":1,"method":"shutdown"}"#;
        let mut input = Vec::new();
        for bad in [
            r#"{"jsonrpc": "2.0", "id": 9, "method": "x", "#,
            r#"[{"jsonrpc":"2.0","id":9,"method":"x"}]"#,
            r#"{"jsonrpc":"2.0","id":9,"method":7}"#,
            r#"{"jsonrpc":"2.0","method":"x","params":{"a":"\ud83d"}}"#,
            r#"{"jsonrpc":"2.0","id":3000000000,"method":"x"}"#,
            r#"{"jsonrpc":"2.0","id":1.5,"method":"x"}"#,
            r#"{"jsonrpc":"2.0","id":null,"method":"x"}"#,
            r#"{"jsonrpc":"2.0","id":true,"method":"x"}"#,
            r#"{"jsonrpc":"2.0","id":{"a":1},"method":"x"}"#,
            "7",
        ] {
            input.extend(frame(bad));
        }
        input.extend(b"\xff\xfe not a header\r\n");
        input.extend(b"Content-Length: 12abc\r\n\r\n");
        input.extend(frame(ok));
        // a header with \n only
        input.extend(format!("Content-Length: {}\n\n{ok}", ok.len()).into_bytes());
        let got = frames(&input);
        let codes: Vec<Option<i64>> = got.iter().map(code).collect();
        assert_eq!(
            codes,
            [
                Some(-32700),
                Some(-32600),
                Some(-32600),
                Some(-32700),
                Some(-32600),
                Some(-32600),
                Some(-32600),
                Some(-32600),
                Some(-32600),
                Some(-32600),
                Some(-32700),
                None,
                None
            ]
        );
        // the ids that can be echoed are
        let Incoming::Reply(r) = &got[4] else {
            panic!()
        };
        assert_eq!(r["id"], json!(3000000000u64));
        let Incoming::Reply(r) = &got[5] else {
            panic!()
        };
        assert_eq!(r["id"], json!(1.5));
        let Incoming::Reply(r) = &got[7] else {
            panic!()
        };
        assert_eq!(r["id"], Value::Null);
    }

    #[test]
    fn huge_lengths_are_refused_without_allocating() {
        // byte counts beyond the limit are refused as soon as their header
        // is read (here the bodies never come); 2^64 overflows: a parse error
        for (n, expected) in [
            ("18446744073709551615", -32600),
            ("1000000000000", -32600),
            ("18446744073709551616", -32700),
        ] {
            let input = format!("Content-Length: {n}\r\n\r\n");
            let got = frames(input.as_bytes());
            assert_eq!(got.len(), 1, "{n}: {got:?}");
            assert_eq!(code(&got[0]), Some(expected), "{n}");
        }
        let mut input = b"Content-Length: 67108865\r\n\r\n".to_vec();
        input.extend(vec![b' '; 67108865]);
        input.extend(frame(
            r#"{"jsonrpc":"2.0","method":"initialized","params":{}}"#,
        ));
        let got = frames(&input);
        assert_eq!(got.len(), 2);
        assert_eq!(code(&got[0]), Some(-32600));
        assert!(matches!(got[1], Incoming::Message(_)));
    }

    #[test]
    fn an_endless_header_line_is_skipped() {
        let mut input = vec![b'x'; 3 * MAX_HEADER_LINE];
        input.extend(b"\r\n");
        input.extend(frame(
            r#"{"jsonrpc":"2.0","method":"initialized","params":{}}"#,
        ));
        let got = frames(&input);
        assert_eq!(code(&got[0]), Some(-32700));
        assert!(matches!(got[1], Incoming::Message(_)));
    }
}

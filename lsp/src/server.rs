//! The server loop: messages in, replies and diagnostics out.

use crate::analysis::Analysis;
use crate::document::Document;
use crate::{complete, diagnostics, hover, inlay, navigate, outline, tokens, transport};
use lsp_server::{Connection, ErrorCode, Message, Notification, Request, Response};
use lsp_types::notification::{
    DidChangeTextDocument, DidCloseTextDocument, DidOpenTextDocument, Exit, Notification as _,
    PublishDiagnostics, ShowMessage,
};
use lsp_types::request::{
    CodeActionRequest, Completion, DocumentSymbolRequest, Formatting, GotoDefinition, HoverRequest,
    InlayHintRequest, PrepareRenameRequest, References, Rename, Request as _,
    SemanticTokensFullRequest,
};
use lsp_types::*;
use serde_json::Value;
use std::collections::HashMap;
use std::fmt;

/// Why the server stopped abnormally.
#[derive(Debug)]
pub enum ServerError {
    /// The client broke the protocol (e.g. no `initialize` first).
    Protocol(String),
    /// Reading or writing the stream failed.
    Io(std::io::Error),
    /// The client sent `exit` without `shutdown` first (LSP: exit code 1).
    ExitWithoutShutdown,
}

impl fmt::Display for ServerError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ServerError::Protocol(m) => write!(f, "protocol error: {m}"),
            ServerError::Io(e) => write!(f, "i/o error: {e}"),
            ServerError::ExitWithoutShutdown => {
                write!(f, "`exit` without a `shutdown` request first")
            }
        }
    }
}

impl std::error::Error for ServerError {}

impl From<lsp_server::ProtocolError> for ServerError {
    fn from(e: lsp_server::ProtocolError) -> Self {
        if e.channel_is_disconnected() {
            return ServerError::Protocol(
                "the input ended before `shutdown` and `exit` (the client went away)".into(),
            );
        }
        ServerError::Protocol(e.to_string())
    }
}

/// What the server announces in its `initialize` reply.
pub fn capabilities() -> ServerCapabilities {
    ServerCapabilities {
        position_encoding: Some(PositionEncodingKind::UTF16),
        text_document_sync: Some(TextDocumentSyncCapability::Kind(
            TextDocumentSyncKind::INCREMENTAL,
        )),
        hover_provider: Some(HoverProviderCapability::Simple(true)),
        completion_provider: Some(CompletionOptions {
            trigger_characters: Some(vec!["[".into(), "=".into(), " ".into()]),
            ..Default::default()
        }),
        definition_provider: Some(OneOf::Left(true)),
        references_provider: Some(OneOf::Left(true)),
        rename_provider: Some(OneOf::Right(RenameOptions {
            prepare_provider: Some(true),
            work_done_progress_options: Default::default(),
        })),
        document_symbol_provider: Some(OneOf::Left(true)),
        document_formatting_provider: Some(OneOf::Left(true)),
        code_action_provider: Some(CodeActionProviderCapability::Simple(true)),
        inlay_hint_provider: Some(OneOf::Left(true)),
        semantic_tokens_provider: Some(SemanticTokensServerCapabilities::SemanticTokensOptions(
            SemanticTokensOptions {
                legend: tokens::legend(),
                full: Some(SemanticTokensFullOptions::Bool(true)),
                range: None,
                work_done_progress_options: Default::default(),
            },
        )),
        ..Default::default()
    }
}

/// The open documents and their analyses.
#[derive(Default)]
pub struct State {
    docs: HashMap<Uri, Analysis>,
}

fn display_name(uri: &Uri) -> String {
    let s = uri.as_str();
    s.rsplit('/').next().unwrap_or(s).to_string()
}

impl State {
    /// Handles a notification; returns the notifications to send (diagnostics).
    pub fn notify(&mut self, n: Notification) -> Vec<Notification> {
        let uri = match n.method.as_str() {
            DidOpenTextDocument::METHOD => {
                let Ok(p) = serde_json::from_value::<DidOpenTextDocumentParams>(n.params) else {
                    return Vec::new();
                };
                let d = p.text_document;
                let doc = Document::new(d.text, d.version);
                self.docs
                    .insert(d.uri.clone(), Analysis::new(doc, &display_name(&d.uri)));
                d.uri
            }
            DidChangeTextDocument::METHOD => {
                let p = match serde_json::from_value::<DidChangeTextDocumentParams>(n.params) {
                    Ok(p) => p,
                    // the editor's text and ours would silently differ: say so
                    Err(e) => {
                        return vec![show_error(format!(
                        "plantc-lsp could not apply a change ({e}); its copy of the document may \
                         differ from the editor's: close and reopen the file"
                    ))]
                    }
                };
                let uri = p.text_document.uri;
                let Some(old) = self.docs.remove(&uri) else {
                    return Vec::new();
                };
                let mut doc = old.doc;
                for c in &p.content_changes {
                    doc.apply(c);
                }
                doc.version = p.text_document.version;
                self.docs
                    .insert(uri.clone(), Analysis::new(doc, &display_name(&uri)));
                uri
            }
            DidCloseTextDocument::METHOD => {
                let Ok(p) = serde_json::from_value::<DidCloseTextDocumentParams>(n.params) else {
                    return Vec::new();
                };
                self.docs.remove(&p.text_document.uri);
                // clear the diagnostics of a closed file
                let params = PublishDiagnosticsParams {
                    uri: p.text_document.uri,
                    diagnostics: Vec::new(),
                    version: None,
                };
                return vec![Notification::new(PublishDiagnostics::METHOD.into(), params)];
            }
            _ => return Vec::new(),
        };
        let a = &self.docs[&uri];
        let params = PublishDiagnosticsParams {
            diagnostics: diagnostics::to_lsp(a, &uri),
            version: Some(a.doc.version),
            uri,
        };
        vec![Notification::new(PublishDiagnostics::METHOD.into(), params)]
    }

    /// Answers a request.
    pub fn request(&self, req: Request) -> Response {
        let id = req.id.clone();
        match self.answer(req) {
            Ok(v) => Response::new_ok(id, v),
            Err((code, msg)) => Response::new_err(id, code as i32, msg),
        }
    }

    fn doc(&self, uri: &Uri) -> Result<&Analysis, (ErrorCode, String)> {
        self.docs.get(uri).ok_or_else(|| {
            (
                ErrorCode::InvalidParams,
                format!("{} is not open", uri.as_str()),
            )
        })
    }

    fn answer(&self, req: Request) -> Result<Value, (ErrorCode, String)> {
        fn params<P: serde::de::DeserializeOwned>(v: Value) -> Result<P, (ErrorCode, String)> {
            serde_json::from_value(v).map_err(|e| (ErrorCode::InvalidParams, e.to_string()))
        }
        fn json<T: serde::Serialize>(v: T) -> Result<Value, (ErrorCode, String)> {
            Ok(serde_json::to_value(v).unwrap_or(Value::Null))
        }
        match req.method.as_str() {
            HoverRequest::METHOD => {
                let p: HoverParams = params(req.params)?;
                let tp = p.text_document_position_params;
                let a = self.doc(&tp.text_document.uri)?;
                json(hover::hover(a, a.doc.offset(tp.position)))
            }
            GotoDefinition::METHOD => {
                let p: GotoDefinitionParams = params(req.params)?;
                let tp = p.text_document_position_params;
                let a = self.doc(&tp.text_document.uri)?;
                json(
                    navigate::definition(a, &tp.text_document.uri, a.doc.offset(tp.position))
                        .map(GotoDefinitionResponse::Scalar),
                )
            }
            References::METHOD => {
                let p: ReferenceParams = params(req.params)?;
                let tp = p.text_document_position;
                let a = self.doc(&tp.text_document.uri)?;
                json(navigate::references(
                    a,
                    &tp.text_document.uri,
                    a.doc.offset(tp.position),
                    p.context.include_declaration,
                ))
            }
            PrepareRenameRequest::METHOD => {
                let p: TextDocumentPositionParams = params(req.params)?;
                let a = self.doc(&p.text_document.uri)?;
                json(navigate::prepare_rename(a, a.doc.offset(p.position)))
            }
            Rename::METHOD => {
                let p: RenameParams = params(req.params)?;
                let tp = p.text_document_position;
                let a = self.doc(&tp.text_document.uri)?;
                let edit = navigate::rename(
                    a,
                    &tp.text_document.uri,
                    a.doc.offset(tp.position),
                    &p.new_name,
                )
                .map_err(|m| (ErrorCode::RequestFailed, m))?;
                json(edit)
            }
            Completion::METHOD => {
                let p: CompletionParams = params(req.params)?;
                let tp = p.text_document_position;
                let a = self.doc(&tp.text_document.uri)?;
                json(CompletionResponse::Array(complete::completion(
                    a,
                    a.doc.offset(tp.position),
                )))
            }
            DocumentSymbolRequest::METHOD => {
                let p: DocumentSymbolParams = params(req.params)?;
                let a = self.doc(&p.text_document.uri)?;
                json(DocumentSymbolResponse::Nested(outline::document_symbols(a)))
            }
            SemanticTokensFullRequest::METHOD => {
                let p: SemanticTokensParams = params(req.params)?;
                let a = self.doc(&p.text_document.uri)?;
                json(SemanticTokensResult::Tokens(tokens::semantic_tokens(a)))
            }
            InlayHintRequest::METHOD => {
                let p: InlayHintParams = params(req.params)?;
                let a = self.doc(&p.text_document.uri)?;
                json(inlay::inlay_hints(a, p.range))
            }
            CodeActionRequest::METHOD => {
                let p: CodeActionParams = params(req.params)?;
                let a = self.doc(&p.text_document.uri)?;
                json(diagnostics::code_actions(a, &p.text_document.uri, p.range))
            }
            Formatting::METHOD => {
                let p: DocumentFormattingParams = params(req.params)?;
                let a = self.doc(&p.text_document.uri)?;
                json(formatting(a))
            }
            other => Err((
                ErrorCode::MethodNotFound,
                format!("method `{other}` is not supported"),
            )),
        }
    }
}

/// A `window/showMessage` error notification.
fn show_error(message: String) -> Notification {
    Notification::new(
        ShowMessage::METHOD.into(),
        ShowMessageParams {
            typ: MessageType::ERROR,
            message,
        },
    )
}

/// `plantc fmt`'s layout as one edit of the lines that change (the common
/// first and last lines are left out, so marks and the cursor elsewhere stay);
/// no edit when the file is already formatted or has syntax errors.
pub fn formatting(a: &Analysis) -> Vec<TextEdit> {
    let text = a.text();
    let Ok(f) = plantc_derive::lang::format::format(text) else {
        return Vec::new();
    };
    if f == text {
        return Vec::new();
    }
    // common prefix and suffix, in whole lines
    let (t, g) = (text.as_bytes(), f.as_bytes());
    let mut pre = t.iter().zip(g).take_while(|(x, y)| x == y).count();
    pre = text[..pre].rfind('\n').map_or(0, |i| i + 1);
    let max_suf = (t.len() - pre).min(g.len() - pre);
    let mut suf = t
        .iter()
        .rev()
        .zip(g.iter().rev())
        .take(max_suf)
        .take_while(|(x, y)| x == y)
        .count();
    // the suffix starts right after a line end (or is empty)
    while suf > 0 && suf < t.len() && t[t.len() - suf - 1] != b'\n' {
        suf -= 1;
    }
    vec![TextEdit {
        range: a
            .doc
            .range(plantc_derive::lang::Span::new(pre, t.len() - suf)),
        new_text: f[pre..g.len() - suf].to_string(),
    }]
}

/// Runs the server on a connection until `shutdown` and `exit`.
pub fn serve(connection: &Connection) -> Result<(), ServerError> {
    let caps = serde_json::to_value(capabilities()).unwrap_or(Value::Null);
    let (id, _params) = connection.initialize_start()?;
    let init = serde_json::json!({
        "capabilities": caps,
        "serverInfo": { "name": "plantc-lsp", "version": env!("CARGO_PKG_VERSION") },
    });
    // not `initialize_finish`, which ends the session when the next message
    // is anything but `initialized`: a client that sends a request first is
    // answered like any other (`initialized` itself is a notification the
    // loop below ignores)
    connection
        .sender
        .send(Response::new_ok(id, init).into())
        .map_err(|e| ServerError::Protocol(format!("cannot send: {e}")))?;
    let mut state = State::default();
    let send = |m: Message| {
        connection
            .sender
            .send(m)
            .map_err(|e| ServerError::Protocol(format!("cannot send: {e}")))
    };
    for msg in &connection.receiver {
        match msg {
            Message::Request(req) => {
                if connection.handle_shutdown(&req)? {
                    return Ok(());
                }
                // a bug in one feature answers with an error instead of ending the session
                let id = req.id.clone();
                let method = req.method.clone();
                let resp = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| state.request(req)))
                    .unwrap_or_else(|_| {
                        Response::new_err(
                            id,
                            ErrorCode::InternalError as i32,
                            format!("plantc-lsp failed on `{method}` (a bug: please report it with the file)"),
                        )
                    });
                send(Message::Response(resp))?;
            }
            Message::Notification(n) if n.method == Exit::METHOD => {
                return Err(ServerError::ExitWithoutShutdown);
            }
            Message::Notification(n) => {
                // a bug in the analysis of one text reports itself instead of
                // ending the session
                let method = n.method.clone();
                let outs =
                    std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| state.notify(n)))
                        .unwrap_or_else(|_| {
                            vec![show_error(format!(
                        "plantc-lsp failed on `{method}` (a bug: please report it with the file)"
                    ))]
                        });
                for out in outs {
                    send(Message::Notification(out))?;
                }
            }
            Message::Response(_) => {}
        }
    }
    Ok(())
}

/// Runs the server over standard input and output (`plantc lsp`), framed
/// by [`crate::transport`]: no input ends it except the end of the stream or
/// `exit`; a malformed frame gets an error reply.
pub fn run_stdio() -> Result<(), ServerError> {
    let (server, client) = Connection::memory();
    let Connection {
        sender: to_server,
        receiver: from_server,
    } = client;
    // frames in: messages to the server, error replies straight out
    std::thread::Builder::new()
        .name("plantc-lsp-reader".into())
        .spawn(move || {
            let stdin = std::io::stdin();
            let mut input = std::io::BufReader::new(stdin.lock());
            while let Ok(Some(incoming)) = transport::read_message(&mut input) {
                match incoming {
                    transport::Incoming::Message(m) => {
                        let exit =
                            matches!(&m, Message::Notification(n) if n.method == Exit::METHOD);
                        if to_server.send(m).is_err() || exit {
                            return;
                        }
                    }
                    transport::Incoming::Reply(v) => {
                        let body = serde_json::to_vec(&v).unwrap_or_default();
                        if transport::write_frame(&mut std::io::stdout().lock(), &body).is_err() {
                            return;
                        }
                    }
                    transport::Incoming::Refused { reply, skip } => {
                        let body = serde_json::to_vec(&reply).unwrap_or_default();
                        if transport::write_frame(&mut std::io::stdout().lock(), &body).is_err()
                            || !matches!(transport::skip_body(&mut input, skip), Ok(true))
                        {
                            return;
                        }
                    }
                }
            }
        })
        .map_err(ServerError::Io)?;
    // messages out, one whole frame at a time
    let writer = std::thread::Builder::new()
        .name("plantc-lsp-writer".into())
        .spawn(move || -> std::io::Result<()> {
            for m in from_server {
                transport::write_message(&mut std::io::stdout().lock(), &m)?;
            }
            Ok(())
        })
        .map_err(ServerError::Io)?;
    let result = serve(&server);
    drop(server);
    let written = writer
        .join()
        .unwrap_or_else(|_| Err(std::io::Error::other("the writer thread panicked")));
    result?;
    written.map_err(ServerError::Io)
}

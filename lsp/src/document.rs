//! An open document: its text, version and the conversion between byte
//! offsets and LSP positions (lines and UTF-16 code units).

use lsp_types::{Position, Range, TextDocumentContentChangeEvent};
use plantc_derive::lang::Span;

/// Text of an open document with a line index.
#[derive(Debug, Clone)]
pub struct Document {
    text: String,
    /// Version given by the client.
    pub version: i32,
    line_starts: Vec<usize>,
}

impl Document {
    /// A document with this text.
    pub fn new(text: String, version: i32) -> Document {
        let mut d = Document {
            text,
            version,
            line_starts: Vec::new(),
        };
        d.reindex();
        d
    }

    /// The current text.
    pub fn text(&self) -> &str {
        &self.text
    }

    fn reindex(&mut self) {
        self.line_starts.clear();
        self.line_starts.push(0);
        for (i, b) in self.text.bytes().enumerate() {
            if b == b'\n' {
                self.line_starts.push(i + 1);
            }
        }
    }

    /// Applies one change of `textDocument/didChange`: a range replacement,
    /// or the whole text when the change has no range.
    pub fn apply(&mut self, change: &TextDocumentContentChangeEvent) {
        match change.range {
            Some(r) => {
                let start = self.offset(r.start);
                let end = self.offset(r.end).max(start);
                self.text.replace_range(start..end, &change.text);
            }
            None => self.text = change.text.clone(),
        }
        self.reindex();
    }

    /// Byte offset of an LSP position (clamped to the line and the text).
    pub fn offset(&self, p: Position) -> usize {
        let line = p.line as usize;
        if line >= self.line_starts.len() {
            return self.text.len();
        }
        let start = self.line_starts[line];
        let end = self
            .line_starts
            .get(line + 1)
            .map_or(self.text.len(), |e| e - 1);
        let mut units = 0u32;
        for (i, c) in self.text[start..end].char_indices() {
            if units >= p.character {
                return start + i;
            }
            units += c.len_utf16() as u32;
        }
        end
    }

    /// LSP position of a byte offset (clamped down to a char boundary).
    pub fn position(&self, offset: usize) -> Position {
        let mut offset = offset.min(self.text.len());
        while !self.text.is_char_boundary(offset) {
            offset -= 1;
        }
        let line = match self.line_starts.binary_search(&offset) {
            Ok(i) => i,
            Err(i) => i - 1,
        };
        let start = self.line_starts[line];
        let character = self.text[start..offset].encode_utf16().count() as u32;
        Position {
            line: line as u32,
            character,
        }
    }

    /// LSP range of a byte span.
    pub fn range(&self, span: Span) -> Range {
        Range {
            start: self.position(span.start),
            end: self.position(span.end.max(span.start)),
        }
    }

    /// Byte span of the 0-based line (without its line end).
    pub fn line_span(&self, line: usize) -> Span {
        let line = line.min(self.line_starts.len() - 1);
        let start = self.line_starts[line];
        let mut end = self
            .line_starts
            .get(line + 1)
            .map_or(self.text.len(), |e| e - 1);
        if end > start && self.text.as_bytes()[end - 1] == b'\r' {
            end -= 1;
        }
        Span::new(start, end)
    }

    /// The range of the whole text.
    pub fn full_range(&self) -> Range {
        self.range(Span::new(0, self.text.len()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pos(line: u32, character: u32) -> Position {
        Position { line, character }
    }

    #[test]
    fn utf16_positions_round_trip() {
        // `α` is 2 bytes and 1 UTF-16 unit, `𝜃` 4 bytes and 2 units
        let d = Document::new("ab\n# α𝜃x\r\nz".into(), 1);
        assert_eq!(d.position(0), pos(0, 0));
        assert_eq!(d.position(3), pos(1, 0));
        let x = d.text().find('x').unwrap();
        assert_eq!(d.position(x), pos(1, 5));
        assert_eq!(d.offset(pos(1, 5)), x);
        assert_eq!(d.offset(pos(1, 3)), d.text().find('𝜃').unwrap());
        assert_eq!(d.offset(pos(2, 0)), d.text().len() - 1);
        assert_eq!(d.offset(pos(9, 9)), d.text().len());
        // past the end of a line: its end
        assert_eq!(d.offset(pos(0, 99)), 2);
    }

    #[test]
    fn incremental_changes_apply_in_order() {
        let mut d = Document::new("let a = 1\nlet b = 2\n".into(), 1);
        let ch = |l0, c0, l1, c1, t: &str| TextDocumentContentChangeEvent {
            range: Some(Range {
                start: pos(l0, c0),
                end: pos(l1, c1),
            }),
            range_length: None,
            text: t.into(),
        };
        d.apply(&ch(1, 8, 1, 9, "α + 3"));
        d.apply(&ch(0, 4, 0, 5, "x"));
        assert_eq!(d.text(), "let x = 1\nlet b = α + 3\n");
        // UTF-16 column after the non-ASCII character
        d.apply(&ch(1, 10, 1, 11, "-"));
        assert_eq!(d.text(), "let x = 1\nlet b = α - 3\n");
        d.apply(&ch(0, 9, 1, 0, " "));
        assert_eq!(d.text(), "let x = 1 let b = α - 3\n");
    }
}

//! An open document: its text, version and the conversion between byte
//! offsets and LSP positions (lines and UTF-16 code units).

use lsp_types::{Position, Range, TextDocumentContentChangeEvent};
use plantc_derive::lang::Span;

/// Bytes per block of the UTF-16 index: a position costs at most one
/// block's scan (64 bytes) after a lookup, whatever the line's length.
const BLOCK: usize = 64;

/// Text of an open document with a line index and a UTF-16 index.
///
/// `units_before[b]` counts the UTF-16 units of the characters that start
/// before byte `b * BLOCK`: a character is one unit, or two when it takes
/// four bytes in UTF-8, and it is counted at its first byte. The UTF-16
/// column of a byte offset is then a difference of two such counts, each a
/// lookup plus a scan of less than a block: a position on a line of `n`
/// bytes costs `O(BLOCK)`, not `O(n)` (40,000 characters on one line made
/// every diagnostic cost a scan of the line: 58 s for its 40,000
/// diagnostics).
#[derive(Debug, Clone)]
pub struct Document {
    text: String,
    /// Version given by the client.
    pub version: i32,
    line_starts: Vec<usize>,
    units_before: Vec<u32>,
}

/// UTF-16 units counted for one UTF-8 byte: at the first byte of a
/// character, 2 for a four-byte character, else 1; 0 for continuation bytes.
fn units_of_byte(b: u8) -> u32 {
    match b {
        0x80..=0xBF => 0,
        0xF0..=0xFF => 2,
        _ => 1,
    }
}

impl Document {
    /// A document with this text.
    pub fn new(text: String, version: i32) -> Document {
        let mut d = Document {
            text,
            version,
            line_starts: Vec::new(),
            units_before: Vec::new(),
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
        self.units_before.clear();
        let mut units = 0u32;
        for (i, b) in self.text.bytes().enumerate() {
            if i % BLOCK == 0 {
                self.units_before.push(units);
            }
            units = units.wrapping_add(units_of_byte(b));
            if b == b'\n' {
                self.line_starts.push(i + 1);
            }
        }
        // the count at the end when it falls on a block boundary
        if self.units_before.len() <= self.text.len() / BLOCK {
            self.units_before.push(units);
        }
    }

    /// UTF-16 units of the characters starting before byte `offset`.
    fn units_to(&self, offset: usize) -> u32 {
        let b = offset / BLOCK;
        let base = self.units_before[b];
        self.text.as_bytes()[b * BLOCK..offset]
            .iter()
            .fold(base, |u, &x| u.wrapping_add(units_of_byte(x)))
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
        // the first character boundary in [start, end] at least
        // `p.character` units from the line start, else `end`
        let target = u64::from(self.units_to(start)) + u64::from(p.character);
        let units_at = |o: usize| u64::from(self.units_to(o));
        if units_at(end) < target {
            return end;
        }
        // the last block boundary at or before the answer, by bisection
        let (mut lo, mut hi) = (start / BLOCK, end / BLOCK);
        while lo < hi {
            let mid = (lo + hi).div_ceil(2);
            if u64::from(self.units_before[mid]) <= target && mid * BLOCK >= start {
                lo = mid;
            } else {
                hi = mid - 1;
            }
        }
        let mut o = (lo * BLOCK).max(start);
        while !self.text.is_char_boundary(o) {
            o += 1;
        }
        let mut units = units_at(o);
        for (i, c) in self.text[o..end].char_indices() {
            if units >= target {
                return o + i;
            }
            units += c.len_utf16() as u64;
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
        let character = self.units_to(offset).wrapping_sub(self.units_to(start));
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

    /// The positions of the former line scan, as the reference.
    fn naive_position(text: &str, offset: usize) -> Position {
        let line_start = text[..offset].rfind('\n').map_or(0, |i| i + 1);
        Position {
            line: text[..offset].matches('\n').count() as u32,
            character: text[line_start..offset].encode_utf16().count() as u32,
        }
    }

    fn naive_offset(text: &str, p: Position) -> usize {
        let mut start = 0;
        for _ in 0..p.line {
            match text[start..].find('\n') {
                Some(i) => start += i + 1,
                None => return text.len(),
            }
        }
        let end = text[start..].find('\n').map_or(text.len(), |i| start + i);
        let mut units = 0;
        for (i, c) in text[start..end].char_indices() {
            if units >= p.character {
                return start + i;
            }
            units += c.len_utf16() as u32;
        }
        end
    }

    proptest::proptest! {
        /// The block index gives the line scan's positions and offsets, on
        /// lines long and short, with 1- to 4-byte characters.
        #[test]
        fn indexed_positions_agree_with_a_line_scan(
            text in "([a\n]|α|€|𝜃|\r\n){0,300}",
            characters in proptest::collection::vec(0u32..400, 8)
        ) {
            let d = Document::new(text.clone(), 1);
            for (o, _) in text.char_indices().chain([(text.len(), ' ')]) {
                proptest::prop_assert_eq!(d.position(o), naive_position(&text, o));
            }
            let lines = text.matches('\n').count() as u32 + 1;
            for (k, c) in characters.iter().enumerate() {
                let p = pos(k as u32 % (lines + 1), *c);
                proptest::prop_assert_eq!(d.offset(p), naive_offset(&text, p), "{:?}", p);
            }
        }
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

//! A line- and token-oriented cursor over the bytes of a text file, for the hand-written parsers.
//!
//! Works on bytes (not `str`) so that stray non-UTF-8 bytes in comments or titles are harmless;
//! tokens are parsed as numbers through `str::from_utf8`.

use super::error::{MeshError, nofile};
use std::str::FromStr;

/// A cursor over lines (split on `\n`, a trailing `\r` removed) and whitespace-separated tokens.
#[derive(Clone)]
pub(crate) struct Cursor<'a> {
    /// Text after the current line.
    rest: &'a [u8],
    /// 1-based number of the current line (0 before the first).
    line: usize,
    /// Unconsumed part of the current line.
    cur: &'a [u8],
}

impl<'a> Cursor<'a> {
    pub(crate) fn new(bytes: &'a [u8]) -> Self {
        Cursor {
            rest: bytes,
            line: 0,
            cur: &[],
        }
    }

    /// Number of the current line (the one the last token or line came from).
    pub(crate) fn line(&self) -> usize {
        self.line
    }

    /// Advance to the next line and return all of it (the current line's remainder is dropped).
    /// The tokens of the returned line are *not* available through [`Cursor::token`].
    pub(crate) fn next_line(&mut self) -> Option<&'a [u8]> {
        if self.rest.is_empty() {
            self.cur = &[];
            return None;
        }
        let (line, rest) = match self.rest.iter().position(|&b| b == b'\n') {
            Some(i) => (&self.rest[..i], &self.rest[i + 1..]),
            None => (self.rest, &self.rest[self.rest.len()..]),
        };
        self.rest = rest;
        self.line += 1;
        self.cur = &[];
        Some(line.strip_suffix(b"\r").unwrap_or(line))
    }

    /// The bytes after the current line.
    pub(crate) fn rest(&self) -> &'a [u8] {
        self.rest
    }

    /// The next non-blank line, trimmed of surrounding whitespace.
    pub(crate) fn next_nonblank_line(&mut self) -> Option<&'a [u8]> {
        loop {
            let l = trim(self.next_line()?);
            if !l.is_empty() {
                return Some(l);
            }
        }
    }

    /// The next whitespace-separated token, crossing line ends.
    pub(crate) fn token(&mut self) -> Option<&'a [u8]> {
        loop {
            let start = self.cur.iter().position(|b| !b.is_ascii_whitespace());
            if let Some(s) = start {
                let tail = &self.cur[s..];
                let len = tail
                    .iter()
                    .position(|b| b.is_ascii_whitespace())
                    .unwrap_or(tail.len());
                let (tok, after) = tail.split_at(len);
                self.cur = after;
                return Some(tok);
            }
            let l = self.next_line()?;
            self.cur = l;
        }
    }

    /// Drop the unconsumed rest of the current line (a comment).
    pub(crate) fn drop_rest_of_line(&mut self) {
        self.cur = &[];
    }

    /// The next token without consuming it.
    pub(crate) fn peek_token(&self) -> Option<&'a [u8]> {
        self.clone().token()
    }

    /// Drop the rest of the current line and skip lines up to and including the next blank one.
    pub(crate) fn skip_past_blank_line(&mut self) {
        while let Some(l) = self.next_line() {
            if trim(l).is_empty() {
                break;
            }
        }
    }

    /// A parse error at the current line.
    pub(crate) fn err(&self, message: impl Into<String>) -> MeshError {
        MeshError::Parse {
            file: nofile(),
            line: self.line.max(1),
            message: message.into(),
        }
    }

    /// The next token, or an "unexpected end of file" error mentioning `what`.
    pub(crate) fn expect_token(&mut self, what: &str) -> Result<&'a [u8], MeshError> {
        self.token().ok_or_else(|| {
            self.err(format!(
                "unexpected end of file while reading {what} (file truncated?)"
            ))
        })
    }

    /// The next token parsed as a number.
    pub(crate) fn number<T: FromStr>(&mut self, what: &str) -> Result<T, MeshError> {
        let tok = self.expect_token(what)?;
        parse_num(tok).ok_or_else(|| self.err(format!("invalid {what} {}", show(tok))))
    }
}

/// Parse a token as a number.
pub(crate) fn parse_num<T: FromStr>(tok: &[u8]) -> Option<T> {
    std::str::from_utf8(tok).ok()?.parse().ok()
}

/// Split a line into whitespace-separated tokens.
pub(crate) fn tokens(line: &[u8]) -> impl Iterator<Item = &[u8]> {
    line.split(|b| b.is_ascii_whitespace())
        .filter(|t| !t.is_empty())
}

/// Strip leading and trailing ASCII whitespace.
pub(crate) fn trim(mut s: &[u8]) -> &[u8] {
    while let [first, rest @ ..] = s {
        if first.is_ascii_whitespace() {
            s = rest;
        } else {
            break;
        }
    }
    while let [rest @ .., last] = s {
        if last.is_ascii_whitespace() {
            s = rest;
        } else {
            break;
        }
    }
    s
}

/// A token or line for an error message: quoted, lossy UTF-8, at most 40 characters.
pub(crate) fn show(tok: &[u8]) -> String {
    let s = String::from_utf8_lossy(tok);
    let short: String = s.chars().take(40).collect();
    if short.len() < s.len() {
        format!("\"{short}...\"")
    } else {
        format!("\"{short}\"")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tokens_cross_lines_and_count_them() {
        let mut c = Cursor::new(b"a b\r\n\n  c\nd");
        assert_eq!(c.token(), Some(&b"a"[..]));
        assert_eq!(c.line(), 1);
        assert_eq!(c.peek_token(), Some(&b"b"[..]));
        assert_eq!(c.token(), Some(&b"b"[..]));
        assert_eq!(c.token(), Some(&b"c"[..]));
        assert_eq!(c.line(), 3);
        assert_eq!(c.next_line(), Some(&b"d"[..]));
        assert_eq!(c.token(), None);
        assert!(c.expect_token("x").is_err());
    }

    #[test]
    fn numbers_and_errors() {
        let mut c = Cursor::new(b"1.5 x\n");
        assert_eq!(c.number::<f64>("value").ok(), Some(1.5));
        let e = c.number::<f64>("x coordinate").unwrap_err().to_string();
        assert_eq!(e, "line 1: invalid x coordinate \"x\"");
        assert_eq!(trim(b"  a b \t"), b"a b");
    }
}

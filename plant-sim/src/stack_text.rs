//! A short text on the stack for the rare events of the 1 kHz loops: formatted with `write!`,
//! cut at its capacity on a char boundary, never touching the heap.

use recordings::EVENT_TEXT_MAX;

/// A short text on the stack for rare events (no heap allocation), as long as an `/events` text.
pub(crate) struct StackText {
    buf: [u8; EVENT_TEXT_MAX],
    len: usize,
}

impl StackText {
    pub(crate) fn new() -> Self {
        StackText { buf: [0; EVENT_TEXT_MAX], len: 0 }
    }
    pub(crate) fn as_str(&self) -> &str {
        std::str::from_utf8(&self.buf[..self.len]).unwrap_or("")
    }
}

impl std::fmt::Write for StackText {
    fn write_str(&mut self, s: &str) -> std::fmt::Result {
        let n = s.len().min(self.buf.len() - self.len);
        // Cut on a char boundary.
        let n = (0..=n).rev().find(|&i| s.is_char_boundary(i)).unwrap_or(0);
        self.buf[self.len..self.len + n].copy_from_slice(&s.as_bytes()[..n]);
        self.len += n;
        Ok(())
    }
}

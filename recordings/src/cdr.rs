//! Minimal little-endian CDR (OMG XCDR1, "CDR_LE", what ROS 2 uses) for flat ROS 2 messages.
//!
//! A message is the 4-byte encapsulation header `00 01 00 00` followed by the fields in schema
//! order; every primitive is aligned to its own size, counted from the end of the header. Fixed
//! arrays have no length prefix; sequences and strings have a `uint32` length (strings count their
//! terminating NUL).

use thiserror::Error;

/// Encapsulation header of plain little-endian CDR.
pub const CDR_LE_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// Appends CDR fields to a reusable buffer.
pub struct CdrWriter<'a> {
    buf: &'a mut Vec<u8>,
}

impl<'a> CdrWriter<'a> {
    /// Clears `buf` and writes the encapsulation header.
    pub fn new(buf: &'a mut Vec<u8>) -> Self {
        buf.clear();
        buf.extend_from_slice(&CDR_LE_HEADER);
        Self { buf }
    }

    fn align(&mut self, n: usize) {
        let off = self.buf.len() - CDR_LE_HEADER.len();
        let pad = (n - off % n) % n;
        self.buf.resize(self.buf.len() + pad, 0);
    }

    pub fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }
    pub fn bool(&mut self, v: bool) {
        self.buf.push(v as u8);
    }
    pub fn u32(&mut self, v: u32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    pub fn i32(&mut self, v: i32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    pub fn i64(&mut self, v: i64) {
        self.u64(v as u64);
    }
    pub fn u64(&mut self, v: u64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    pub fn f64(&mut self, v: f64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    /// A fixed-size `float64[N]` array (no length prefix).
    pub fn f64_array(&mut self, v: &[f64]) {
        self.align(8);
        for x in v {
            self.buf.extend_from_slice(&x.to_le_bytes());
        }
    }
    /// A `float32[]` sequence.
    pub fn f32_seq(&mut self, v: impl ExactSizeIterator<Item = f32>) {
        self.u32(v.len() as u32);
        for x in v {
            self.buf.extend_from_slice(&x.to_le_bytes());
        }
    }
    pub fn string(&mut self, s: &str) {
        self.u32(s.len() as u32 + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }
}

/// A malformed CDR message.
#[derive(Debug, Error, PartialEq)]
pub enum CdrError {
    #[error("CDR message has encapsulation header {0:02x?}, expected little-endian CDR {CDR_LE_HEADER:02x?}")]
    Header([u8; 2]),
    #[error("CDR message ends at byte {len} while reading field `{field}` at byte {at}")]
    Short { field: &'static str, at: usize, len: usize },
    #[error("CDR field `{field}` is not valid UTF-8")]
    Utf8 { field: &'static str },
}

/// Reads CDR fields in schema order.
pub struct CdrReader<'a> {
    body: &'a [u8],
    pos: usize,
}

impl<'a> CdrReader<'a> {
    pub fn new(msg: &'a [u8]) -> Result<Self, CdrError> {
        if msg.len() < 4 {
            return Err(CdrError::Short { field: "encapsulation header", at: 0, len: msg.len() });
        }
        if msg[0] != CDR_LE_HEADER[0] || msg[1] != CDR_LE_HEADER[1] {
            return Err(CdrError::Header([msg[0], msg[1]]));
        }
        Ok(Self { body: &msg[4..], pos: 0 })
    }

    fn take(&mut self, n: usize, align: usize, field: &'static str) -> Result<&'a [u8], CdrError> {
        let start = self.pos.div_ceil(align) * align;
        let end = start + n;
        if end > self.body.len() {
            return Err(CdrError::Short { field, at: start + 4, len: self.body.len() + 4 });
        }
        self.pos = end;
        Ok(&self.body[start..end])
    }

    pub fn u8(&mut self, field: &'static str) -> Result<u8, CdrError> {
        Ok(self.take(1, 1, field)?[0])
    }
    pub fn bool(&mut self, field: &'static str) -> Result<bool, CdrError> {
        Ok(self.u8(field)? != 0)
    }
    pub fn u32(&mut self, field: &'static str) -> Result<u32, CdrError> {
        Ok(u32::from_le_bytes(self.take(4, 4, field)?.try_into().unwrap()))
    }
    pub fn i32(&mut self, field: &'static str) -> Result<i32, CdrError> {
        Ok(i32::from_le_bytes(self.take(4, 4, field)?.try_into().unwrap()))
    }
    pub fn i64(&mut self, field: &'static str) -> Result<i64, CdrError> {
        Ok(self.u64(field)? as i64)
    }
    /// True when every byte of the message is read (a message of an older, shorter schema).
    pub fn at_end(&self) -> bool {
        self.pos >= self.body.len()
    }
    pub fn u64(&mut self, field: &'static str) -> Result<u64, CdrError> {
        Ok(u64::from_le_bytes(self.take(8, 8, field)?.try_into().unwrap()))
    }
    pub fn f64(&mut self, field: &'static str) -> Result<f64, CdrError> {
        Ok(f64::from_le_bytes(self.take(8, 8, field)?.try_into().unwrap()))
    }
    pub fn f64_array<const N: usize>(&mut self, field: &'static str) -> Result<[f64; N], CdrError> {
        let bytes = self.take(8 * N, 8, field)?;
        let mut out = [0.0; N];
        for (o, c) in out.iter_mut().zip(bytes.chunks_exact(8)) {
            *o = f64::from_le_bytes(c.try_into().unwrap());
        }
        Ok(out)
    }
    pub fn f32_seq(&mut self, field: &'static str) -> Result<Vec<f32>, CdrError> {
        let n = self.u32(field)? as usize;
        let bytes = self.take(4 * n, 4, field)?;
        Ok(bytes.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect())
    }
    pub fn string(&mut self, field: &'static str) -> Result<String, CdrError> {
        let n = self.u32(field)? as usize;
        let bytes = self.take(n, 1, field)?;
        let text = bytes.strip_suffix(&[0]).unwrap_or(bytes);
        String::from_utf8(text.to_vec()).map_err(|_| CdrError::Utf8 { field })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn alignment_counts_from_after_the_header() {
        // u8 at 0, u32 padded to 4, u8 at 8, f64 padded to 16: 24 body bytes (OMG CDR alignment).
        let mut buf = Vec::new();
        let mut w = CdrWriter::new(&mut buf);
        w.u8(7);
        w.u32(0x0102_0304);
        w.u8(9);
        w.f64(1.5);
        assert_eq!(buf.len(), 4 + 24);
        assert_eq!(&buf[..4], &CDR_LE_HEADER);
        assert_eq!(&buf[4 + 4..4 + 8], &[4, 3, 2, 1]);
        assert_eq!(&buf[4 + 16..], &1.5f64.to_le_bytes());
        assert_eq!(&buf[4 + 1..4 + 4], &[0, 0, 0]);
    }

    #[test]
    fn string_counts_its_nul_and_round_trips() {
        let mut buf = Vec::new();
        let mut w = CdrWriter::new(&mut buf);
        w.bool(true);
        w.string("safe stop");
        w.f32_seq([1.0f32, -2.5].into_iter());
        w.f64_array(&[1.0, 2.0, 3.0]);
        w.i32(-5);
        assert_eq!(u32::from_le_bytes(buf[8..12].try_into().unwrap()), 10);
        let mut r = CdrReader::new(&buf).unwrap();
        assert!(r.bool("b").unwrap());
        assert_eq!(r.string("s").unwrap(), "safe stop");
        assert_eq!(r.f32_seq("p").unwrap(), vec![1.0, -2.5]);
        assert_eq!(r.f64_array::<3>("a").unwrap(), [1.0, 2.0, 3.0]);
        assert_eq!(r.i32("i").unwrap(), -5);
        assert!(matches!(r.u8("past end"), Err(CdrError::Short { field: "past end", .. })));
    }

    #[test]
    fn big_endian_or_garbage_is_refused() {
        assert_eq!(CdrReader::new(&[0, 0, 0, 0, 1]).err(), Some(CdrError::Header([0, 0])));
        assert!(matches!(CdrReader::new(&[0, 1]).err(), Some(CdrError::Short { .. })));
    }
}

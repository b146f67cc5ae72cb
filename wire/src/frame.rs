//! Framing: 0x00 + COBS(postcard + CRC-32) + 0x00, and a decoder that survives garbage.

use serde::de::DeserializeOwned;
use serde::Serialize;

use crate::cobs;
use crate::MAX_FRAME;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EncodeError {
    /// The message does not fit a frame (or the output buffer).
    TooLarge,
}

/// Largest postcard body a frame carries: with the CRC, COBS's overhead and
/// both delimiters it is exactly [`MAX_FRAME`] bytes on the wire.
const MAX_BODY: usize = MAX_FRAME - 8;
const _: () = assert!(cobs::max_encoded_len(MAX_BODY + 4) + 2 == MAX_FRAME);

/// Writes one complete frame of `msg` into `out`; returns its length.
///
/// The frame starts with a delimiter as well as ending with one: line noise
/// (or a frame cut short) before it then ends at that 0x00 as a bad frame of
/// its own instead of merging with this one. Between back-to-back frames the
/// two delimiters make an empty frame, which every decoder ignores.
pub fn encode<T: Serialize>(msg: &T, out: &mut [u8]) -> Result<usize, EncodeError> {
    let mut raw = [0u8; MAX_FRAME];
    let body = postcard::to_slice(msg, &mut raw[..MAX_BODY]).map_err(|_| EncodeError::TooLarge)?;
    let n = body.len();
    let crc = hammer_types::crc32(&raw[..n]);
    raw[n..n + 4].copy_from_slice(&crc.to_le_bytes());
    let limit = out.len().min(MAX_FRAME);
    if cobs::max_encoded_len(n + 4) + 2 > limit {
        return Err(EncodeError::TooLarge);
    }
    out[0] = 0;
    let m = cobs::encode(&raw[..n + 4], &mut out[1..limit - 1]).ok_or(EncodeError::TooLarge)?;
    out[m + 1] = 0;
    Ok(m + 2)
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DecodeError {
    /// Not valid COBS (a corrupted or truncated frame).
    Cobs,
    /// The checksum does not match: bytes were corrupted on the way.
    Crc,
    /// Intact bytes that are not a known message (another protocol version?).
    Message,
    /// Longer than any frame: discarded up to the next delimiter.
    Oversize,
}

/// What the decoder has seen; every byte ends up counted somewhere.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DecoderStats {
    pub frames: u32,
    pub cobs_errors: u32,
    pub crc_errors: u32,
    pub message_errors: u32,
    pub oversize: u32,
    /// Bytes thrown away with bad or oversize frames.
    pub discarded_bytes: u32,
}

/// Accumulates bytes and yields messages at each delimiter. Bounded: `N` bytes.
pub struct Decoder<const N: usize = MAX_FRAME> {
    buf: [u8; N],
    len: usize,
    overflow: bool,
    pub stats: DecoderStats,
}

impl<const N: usize> Default for Decoder<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> Decoder<N> {
    pub const fn new() -> Self {
        Self {
            buf: [0; N],
            len: 0,
            overflow: false,
            stats: DecoderStats {
                frames: 0,
                cobs_errors: 0,
                crc_errors: 0,
                message_errors: 0,
                oversize: 0,
                discarded_bytes: 0,
            },
        }
    }

    /// Feeds one byte; returns `Some` when it completed a frame (good or bad).
    pub fn push<T: DeserializeOwned>(&mut self, byte: u8) -> Option<Result<T, DecodeError>> {
        self.push_with(byte, |body| match postcard::take_from_bytes::<T>(body) {
            Ok((m, [])) => Some(m),
            _ => None,
        })
    }

    /// [`Self::push`] with the message read from the frame's checked body by
    /// `parse` (`None`: not a message): a host reads an older protocol's
    /// recording this way (`crate::legacy`).
    pub fn push_with<T>(&mut self, byte: u8, parse: impl FnOnce(&[u8]) -> Option<T>) -> Option<Result<T, DecodeError>> {
        if byte != 0 {
            if self.len < N {
                self.buf[self.len] = byte;
                self.len += 1;
            } else {
                self.overflow = true;
                self.stats.discarded_bytes = self.stats.discarded_bytes.saturating_add(1);
            }
            return None;
        }
        let len = core::mem::replace(&mut self.len, 0);
        if core::mem::replace(&mut self.overflow, false) {
            self.stats.oversize = self.stats.oversize.saturating_add(1);
            self.stats.discarded_bytes = self.stats.discarded_bytes.saturating_add(len as u32);
            return Some(Err(DecodeError::Oversize));
        }
        if len == 0 {
            return None; // back-to-back delimiters: an idle line, not a frame
        }
        let result = self.decode(len, parse);
        match result {
            Ok(_) => self.stats.frames = self.stats.frames.saturating_add(1),
            Err(e) => {
                self.stats.discarded_bytes = self.stats.discarded_bytes.saturating_add(len as u32);
                let c = match e {
                    DecodeError::Cobs => &mut self.stats.cobs_errors,
                    DecodeError::Crc => &mut self.stats.crc_errors,
                    DecodeError::Message => &mut self.stats.message_errors,
                    DecodeError::Oversize => &mut self.stats.oversize,
                };
                *c = c.saturating_add(1);
            }
        }
        Some(result)
    }

    fn decode<T>(&mut self, len: usize, parse: impl FnOnce(&[u8]) -> Option<T>) -> Result<T, DecodeError> {
        let n = cobs::decode_in_place(&mut self.buf[..len]).ok_or(DecodeError::Cobs)?;
        if n < 5 {
            return Err(if n < 4 { DecodeError::Cobs } else { DecodeError::Message });
        }
        let body = &self.buf[..n - 4];
        let crc = u32::from_le_bytes([self.buf[n - 4], self.buf[n - 3], self.buf[n - 2], self.buf[n - 1]]);
        if crc != hammer_types::crc32(body) {
            return Err(DecodeError::Crc);
        }
        parse(body).ok_or(DecodeError::Message)
    }
}

//! Framing: `COBS(payload ++ CRC-32(payload) as 4 LE bytes) ++ 0x00`.
//!
//! COBS removes every zero from the encoded bytes, so `0x00` ends a frame and a receiver that
//! lost bytes (a link unplugged mid-transfer, noise) resynchronises at the next zero. The CRC-32
//! (IEEE 802.3, bitwise: no table in flash) catches corrupted bytes. Sizes are bounded on both
//! sides: a payload is at most [`MAX_PAYLOAD`] bytes, an encoded frame at most [`MAX_FRAME`];
//! a longer one is dropped whole by [`FrameReader`] and reported as [`FrameError::TooLong`].

use serde::{Deserialize, Serialize};

use crate::wire::Header;

/// Largest payload (postcard bytes of header and message), bytes: a vehicle record
/// (`shimmy_core::vehicle::RECORD_MAX_BYTES`) plus its response envelope, with room to spare.
pub const MAX_PAYLOAD: usize = 832;
/// Bytes of the CRC after the payload.
pub const CRC_BYTES: usize = 4;
/// Largest encoded frame without its `0x00` delimiter: COBS adds one byte per 254 and one more.
pub const MAX_FRAME: usize = MAX_PAYLOAD + CRC_BYTES + (MAX_PAYLOAD + CRC_BYTES) / 254 + 1;
/// The frame delimiter.
pub const DELIMITER: u8 = 0;

static CRC32: crc::Crc<u32, crc::NoTable> =
    crc::Crc::<u32, crc::NoTable>::new(&crc::CRC_32_ISO_HDLC);

/// Why a frame could not be written or read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameError {
    /// More than [`MAX_FRAME`] bytes before a delimiter (the frame is dropped whole).
    TooLong,
    /// Not valid COBS (a zero where none can be, a truncated block).
    Cobs,
    /// Shorter than its CRC.
    Short,
    /// The CRC does not match the bytes (corrupted in transit).
    Crc,
    /// The header is unreadable.
    Header,
    /// The message does not fit [`MAX_PAYLOAD`] (a sender-side bound).
    PayloadTooLong,
}

impl FrameError {
    /// What went wrong, for messages.
    pub const fn text(self) -> &'static str {
        match self {
            FrameError::TooLong => "frame too long (no delimiter within the bound)",
            FrameError::Cobs => "frame is not valid COBS",
            FrameError::Short => "frame shorter than its CRC",
            FrameError::Crc => "frame CRC mismatch (corrupted in transit)",
            FrameError::Header => "frame header unreadable",
            FrameError::PayloadTooLong => "message longer than the payload bound",
        }
    }
}

/// Encodes `header` and `body` as one frame into `out` (delimiter included); returns its length.
/// The bytes stream through the CRC and the COBS encoder straight into `out` (no payload copy
/// on the stack).
pub fn encode<T: Serialize>(header: Header, body: &T, out: &mut [u8]) -> Result<usize, FrameError> {
    // One byte of `out` stays free for the delimiter.
    let room = out.len().saturating_sub(1);
    let n = {
        let Some(room) = out.get_mut(..room) else {
            return Err(FrameError::PayloadTooLong);
        };
        let framer = Framer {
            cobs: cobs::CobsEncoder::new(room),
            crc: CRC32.digest(),
            len: 0,
        };
        postcard::serialize_with_flavor(&(header, body), framer)
            .map_err(|_| FrameError::PayloadTooLong)?
    };
    let Some(end) = out.get_mut(n) else {
        return Err(FrameError::PayloadTooLong);
    };
    *end = DELIMITER;
    Ok(n + 1)
}

/// A postcard flavor: payload bytes into the CRC and the COBS encoder; at the end the CRC.
struct Framer<'a> {
    cobs: cobs::CobsEncoder<'a>,
    crc: crc::Digest<'static, u32, crc::NoTable>,
    len: usize,
}

impl postcard::ser_flavors::Flavor for Framer<'_> {
    type Output = usize;

    fn try_push(&mut self, byte: u8) -> postcard::Result<()> {
        self.try_extend(&[byte])
    }

    // One out-of-line copy for every serialised field (postcard's default loops `try_push`,
    // inlined at each field: ~1.4 KB of the firmware image).
    #[inline(never)]
    fn try_extend(&mut self, bytes: &[u8]) -> postcard::Result<()> {
        self.len += bytes.len();
        if self.len > MAX_PAYLOAD {
            return Err(postcard::Error::SerializeBufferFull);
        }
        self.crc.update(bytes);
        self.cobs
            .push(bytes)
            .map_err(|_| postcard::Error::SerializeBufferFull)
    }

    fn finalize(mut self) -> postcard::Result<usize> {
        let crc = self.crc.finalize();
        self.cobs
            .push(&crc.to_le_bytes())
            .map_err(|_| postcard::Error::SerializeBufferFull)?;
        Ok(self.cobs.finalize())
    }
}

/// Decodes one frame (its COBS bytes without the delimiter, decoded in place) and checks its
/// CRC; returns the header and the message bytes after it.
pub fn decode(frame: &mut [u8]) -> Result<(Header, &[u8]), FrameError> {
    if frame.len() > MAX_FRAME {
        return Err(FrameError::TooLong);
    }
    let n = cobs::decode_in_place(frame).map_err(|_| FrameError::Cobs)?;
    let Some(body) = n.checked_sub(CRC_BYTES) else {
        return Err(FrameError::Short);
    };
    let (payload, crc) = frame.get(..n).unwrap_or_default().split_at(body);
    let crc = <[u8; 4]>::try_from(crc).map_err(|_| FrameError::Short)?;
    if CRC32.checksum(payload) != u32::from_le_bytes(crc) {
        return Err(FrameError::Crc);
    }
    postcard::take_from_bytes::<Header>(payload).map_err(|_| FrameError::Header)
}

/// Reads the message of a decoded frame; `None` when the bytes are no `T` (an unknown request
/// or response kind, a truncated field).
pub fn message<'a, T: Deserialize<'a>>(bytes: &'a [u8]) -> Option<T> {
    postcard::from_bytes(bytes).ok()
}

/// Splits a byte stream into frames, bounded by [`MAX_FRAME`].
#[derive(Debug)]
pub struct FrameReader {
    buf: [u8; MAX_FRAME],
    len: usize,
    overflow: bool,
}

/// What one byte fed to a [`FrameReader`] completed.
#[derive(Debug, PartialEq, Eq)]
pub enum Fed<'a> {
    /// The frame is not complete yet.
    Pending,
    /// A complete frame (COBS bytes, without the delimiter); decode it with [`decode`].
    Frame(&'a mut [u8]),
    /// A frame longer than [`MAX_FRAME`] ended here; it was dropped.
    TooLong,
}

impl Default for FrameReader {
    fn default() -> Self {
        Self::new()
    }
}

impl FrameReader {
    /// An empty reader.
    pub const fn new() -> Self {
        FrameReader {
            buf: [0; MAX_FRAME],
            len: 0,
            overflow: false,
        }
    }

    /// Drops a partial frame (e.g. after a timeout: the rest will not come).
    pub fn reset(&mut self) {
        self.len = 0;
        self.overflow = false;
    }

    /// A partial frame is buffered.
    pub fn partial(&self) -> bool {
        self.len > 0 || self.overflow
    }

    /// Feeds one byte. Empty frames (two delimiters in a row) are skipped.
    pub fn feed(&mut self, byte: u8) -> Fed<'_> {
        if byte == DELIMITER {
            let (len, overflow) = (self.len, self.overflow);
            self.reset();
            return if overflow {
                Fed::TooLong
            } else if len == 0 {
                Fed::Pending
            } else {
                match self.buf.get_mut(..len) {
                    Some(frame) => Fed::Frame(frame),
                    None => Fed::TooLong,
                }
            };
        }
        match self.buf.get_mut(self.len) {
            Some(slot) if !self.overflow => {
                *slot = byte;
                self.len += 1;
            }
            _ => {
                self.overflow = true;
                self.len = 0;
            }
        }
        Fed::Pending
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::{Request, PROTOCOL_HEADER};

    fn header(seq: u16) -> Header {
        Header {
            seq,
            ..PROTOCOL_HEADER
        }
    }

    fn frames(
        bytes: &[u8],
        reader: &mut FrameReader,
    ) -> std::vec::Vec<Result<(Header, std::vec::Vec<u8>), FrameError>> {
        let mut out = std::vec::Vec::new();
        for &b in bytes {
            match reader.feed(b) {
                Fed::Pending => {}
                Fed::TooLong => out.push(Err(FrameError::TooLong)),
                Fed::Frame(f) => out.push(decode(f).map(|(h, m)| (h, m.to_vec()))),
            }
        }
        out
    }

    #[test]
    fn a_frame_round_trips_and_has_no_zero_inside() {
        let mut out = [0u8; MAX_FRAME + 1];
        let record = [0u8; 300]; // zeros: COBS must remove every one
        let n = encode(header(7), &Request::SetConfig(&record), &mut out).unwrap();
        assert!(out[..n - 1].iter().all(|&b| b != 0));
        assert_eq!(out[n - 1], 0);
        let got = frames(&out[..n], &mut FrameReader::new());
        let (h, m) = got[0].clone().unwrap();
        assert_eq!(h, header(7));
        assert_eq!(
            message::<Request<'_>>(&m),
            Some(Request::SetConfig(&record))
        );
    }

    #[test]
    fn every_single_bit_flip_is_caught() {
        let mut out = [0u8; MAX_FRAME + 1];
        let n = encode(header(1), &Request::ReadEvents { first: 3 }, &mut out).unwrap();
        for i in 0..n - 1 {
            for bit in 0..8 {
                let mut f = out;
                f[i] ^= 1 << bit;
                let mut r = FrameReader::new();
                // A flip to zero splits the frame: each part must fail on its own.
                for res in frames(&f[..n], &mut r) {
                    assert!(res.is_err(), "flip at byte {i} bit {bit} passed");
                }
            }
        }
    }

    #[test]
    fn an_overlong_frame_is_dropped_whole_and_the_next_one_reads() {
        let mut stream = std::vec![0x55u8; MAX_FRAME + 10];
        stream.push(0);
        let mut out = [0u8; MAX_FRAME + 1];
        let n = encode(header(2), &Request::Identify, &mut out).unwrap();
        stream.extend_from_slice(&out[..n]);
        let got = frames(&stream, &mut FrameReader::new());
        assert_eq!(got.len(), 2);
        assert_eq!(got[0], Err(FrameError::TooLong));
        assert_eq!(got[1].as_ref().unwrap().0, header(2));
    }

    #[test]
    fn a_frame_cut_short_fails_and_the_reader_resynchronises() {
        let mut out = [0u8; MAX_FRAME + 1];
        let n = encode(header(3), &Request::ReadFaults, &mut out).unwrap();
        let mut stream = out[..n / 2].to_vec(); // unplugged mid-frame...
        stream.push(0); // ...the next frame's delimiter arrives after reconnecting
        stream.extend_from_slice(&out[..n]);
        let got = frames(&stream, &mut FrameReader::new());
        assert!(got[0].is_err());
        assert_eq!(got[1].as_ref().unwrap().0, header(3));
    }

    #[test]
    fn a_payload_beyond_the_bound_is_refused_by_the_sender() {
        let mut out = [0u8; MAX_FRAME + 1];
        let big = [1u8; MAX_PAYLOAD];
        assert_eq!(
            encode(header(4), &Request::SetConfig(&big), &mut out),
            Err(FrameError::PayloadTooLong)
        );
    }

    #[test]
    fn the_largest_vehicle_record_fits_a_frame() {
        let mut out = [0u8; MAX_FRAME + 1];
        let rec = [0xAAu8; shimmy_core::vehicle::RECORD_MAX_BYTES];
        let reply = crate::wire::Response::Config {
            record: &rec,
            pending: true,
        };
        assert!(encode(header(5), &reply, &mut out).is_ok());
    }

    /// A full page of the longest entries, with the largest counts (postcard's varints at their
    /// longest), fits a frame: the device never has to cut a page short.
    #[test]
    fn a_full_page_of_the_longest_entries_fits_a_frame() {
        use crate::wire::{EventPage, LogEntry, Response, ShimmyEvent, EVENTS_PER_PAGE};
        let e = LogEntry::Shimmy(ShimmyEvent {
            start_s: 1e9,
            speed_mps: 70.0,
            freq_hz: 40.0,
            peak_amplitude_rad: 0.5,
            duration_s: 1e6,
            shimmy_s: 1e6,
            level: 3,
            open: true,
            peak_current_a: 2.0,
            mean_current_a: 2.0,
        });
        let mut entries = heapless::Vec::new();
        while entries.push(e).is_ok() {}
        assert_eq!(entries.len(), EVENTS_PER_PAGE);
        let reply = Response::Events(EventPage {
            kept: u16::MAX,
            dropped: u32::MAX,
            first: u16::MAX,
            entries,
        });
        let mut out = [0u8; MAX_FRAME + 1];
        let n = encode(header(u16::MAX), &reply, &mut out).unwrap();
        assert!(n <= MAX_FRAME + 1, "{n}");
    }
}

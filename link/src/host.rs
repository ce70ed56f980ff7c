//! The host side's reading of a device frame: the frame checks ([`frame::decode`]), the
//! protocol version and the response kind in one place, so a host tool never acts on a reply
//! of a schema it does not speak (the fields of another version may mean something else).

use core::fmt;

use crate::frame::{self, FrameError};
use crate::wire::{Header, Response, PROTOCOL_HEADER};
use crate::PROTOCOL_VERSION;

/// Why a frame from the device is no reply this host can use.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReplyError {
    /// The frame failed COBS, CRC or header checks.
    Frame(FrameError),
    /// The frame is of another protocol version than [`PROTOCOL_VERSION`].
    Version {
        /// The version in the frame's header.
        received: u16,
    },
    /// A response kind this version does not have (or a truncated field).
    UnknownResponse,
}

impl fmt::Display for ReplyError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ReplyError::Frame(e) => write!(f, "damaged frame from the device: {}", e.text()),
            ReplyError::Version { received } => write!(
                f,
                "the device replied in protocol version {received}; this tool supports version \
                 {PROTOCOL_VERSION} only"
            ),
            ReplyError::UnknownResponse => write!(
                f,
                "the device sent a reply this tool does not know (protocol {PROTOCOL_VERSION})"
            ),
        }
    }
}

/// Reads one frame from the device (its COBS bytes without the delimiter, decoded in place).
/// Returns the header as read (seq 0 when the frame is damaged) and the response, or why there
/// is none.
pub fn decode_reply(frame: &mut [u8]) -> (Header, Result<Response<'_>, ReplyError>) {
    match frame::decode(frame) {
        Err(e) => (PROTOCOL_HEADER, Err(ReplyError::Frame(e))),
        Ok((h, _)) if h.version != PROTOCOL_VERSION => (
            h,
            Err(ReplyError::Version {
                received: h.version,
            }),
        ),
        Ok((h, body)) => match frame::message::<Response<'_>>(body) {
            Some(r) => (h, Ok(r)),
            None => (h, Err(ReplyError::UnknownResponse)),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::{encode, MAX_FRAME};
    use crate::wire::Response;

    fn frame_of(h: Header, r: &Response<'_>) -> std::vec::Vec<u8> {
        let mut out = [0u8; MAX_FRAME + 1];
        let n = encode(h, r, &mut out).unwrap();
        out[..n - 1].to_vec()
    }

    #[test]
    fn a_reply_of_this_version_reads() {
        let h = Header {
            seq: 5,
            ..PROTOCOL_HEADER
        };
        let mut f = frame_of(h, &Response::Cleared { removed: 3 });
        assert_eq!(
            decode_reply(&mut f),
            (h, Ok(Response::Cleared { removed: 3 }))
        );
    }

    #[test]
    fn a_reply_of_another_version_is_refused_naming_both_versions() {
        let h = Header {
            version: PROTOCOL_VERSION + 7,
            seq: 5,
        };
        let mut f = frame_of(h, &Response::Cleared { removed: 3 });
        let (got, r) = decode_reply(&mut f);
        assert_eq!(
            got.seq, 5,
            "the seq stays, so the waiting request gets the error"
        );
        let e = r.unwrap_err();
        assert_eq!(
            e,
            ReplyError::Version {
                received: PROTOCOL_VERSION + 7
            }
        );
        let text = std::format!("{e}");
        assert!(
            text.contains(&std::format!("version {}", PROTOCOL_VERSION + 7))
                && text.contains(&std::format!("version {PROTOCOL_VERSION}")),
            "{text}"
        );
    }

    #[test]
    fn a_damaged_or_unknown_reply_is_an_error() {
        let mut f = frame_of(PROTOCOL_HEADER, &Response::Cleared { removed: 3 });
        f[2] ^= 0x10;
        assert!(matches!(
            decode_reply(&mut f).1,
            Err(ReplyError::Frame(FrameError::Crc | FrameError::Cobs))
        ));
        let mut out = [0u8; MAX_FRAME + 1];
        let n = encode(PROTOCOL_HEADER, &(200u8,), &mut out).unwrap();
        assert_eq!(
            decode_reply(&mut out[..n - 1]).1,
            Err(ReplyError::UnknownResponse)
        );
    }
}

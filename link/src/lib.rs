//! The host link of the shimmy damper controller: how a laptop configures a board, reads back
//! its event log and fault record and watches its margin report live.
//!
//! Shared, `no_std` and heapless, by the firmware, the simulator's in-process device and the
//! host tool (`shimmy-sim device ...`):
//!
//! - [`wire`]: the typed messages. Every frame starts with a [`wire::Header`] carrying
//!   [`PROTOCOL_VERSION`]; the vehicle configuration travels as the core's vehicle record
//!   (`Vehicle::encode_record`), never as a second encoding of the vehicle.
//! - [`frame`]: postcard payload + CRC-32, COBS-encoded, `0x00`-terminated; every size bounded
//!   ([`frame::MAX_PAYLOAD`], [`frame::MAX_FRAME`]).
//! - [`device`]: the device side as a transport-independent handler (request bytes in, response
//!   bytes out) over a [`device::Backend`] (configuration, event log, fault record, identity,
//!   telemetry). Anything it does not understand gets an error reply, never a hang or a panic.
//! - [`host`]: the host side's reading of a device frame ([`host::decode_reply`]): a reply of
//!   another protocol version is refused, never read as this version's.
#![no_std]

#[cfg(test)]
extern crate std;

pub mod device;
pub mod frame;
pub mod host;
pub mod log;
pub mod wire;

/// Version of the message schema; a frame of another version is answered with
/// [`wire::ErrorReply::Version`]. Raise it on any change of [`wire`]'s types.
pub const PROTOCOL_VERSION: u16 = 4;

/// Serial speed of the link, baud (the board's USART1 and the host tool's default): a 0.8 KiB
/// reply (a vehicle record) takes 9 ms on the wire.
pub const LINK_BAUD: u32 = 921_600;

//! Random bytes from the link into the host's decoder of device frames
//! (`shimmy_link::host::decode_reply`) and into the device's request handler
//! (`shimmy_link::device::Device::on_byte`). The first byte chooses how the rest is sent: as
//! raw bytes (the frame checks see them), or as a random message in a valid frame of this or
//! another protocol version (past the CRC, which random bytes almost never pass).
//!
//! Checked on every input: no panic; the decoder reads only replies of this version; the
//! handler answers every frame with a reply of this version that the host reads, and changes
//! the backend only for a request it acknowledged.
//!
//! Run: `cargo xtask fuzz --target link_frames` (part of `cargo xtask test`).
#![no_main]

use libfuzzer_sys::fuzz_target;
use shimmy_core::vehicle::Vehicle;
use shimmy_link::device::{Backend, Device, REPLY_BYTES};
use shimmy_link::frame::{self, Fed, FrameReader, MAX_FRAME, MAX_PAYLOAD};
use shimmy_link::host::decode_reply;
use shimmy_link::log::{EventSink, Pager, RamLog};
use shimmy_link::wire::{
    ErrorReply, FaultEvent, FaultReport, Header, Identity, LogEntry, ModelReport, Response,
    Telemetry,
};
use shimmy_link::PROTOCOL_VERSION;

/// A device's state in RAM: a vehicle, a log of a few entries, moving (so a clear is refused
/// unless `standstill`).
struct Ram {
    vehicle: Vehicle,
    pending: bool,
    standstill: bool,
    log: RamLog<20>,
}

impl Backend for Ram {
    type Vehicle = Vehicle;
    fn identity(&self) -> Identity<'_> {
        Identity {
            firmware: "fuzz",
            core: shimmy_core::VERSION,
            protocol: PROTOCOL_VERSION,
            vehicle_schema: shimmy_core::vehicles::car::board::record_schema(),
            log_capacity: 20,
        }
    }
    fn vehicle(&self) -> (&Vehicle, bool) {
        (&self.vehicle, self.pending)
    }
    fn store_vehicle(&mut self, v: Vehicle) -> bool {
        self.vehicle = v;
        self.pending = !self.standstill;
        self.standstill
    }
    fn read_log(&mut self, pager: &mut Pager<'_>) -> Result<(u16, u32), ErrorReply<'static>> {
        Ok(self.log.page(None, pager))
    }
    fn clear_log(&mut self) -> Result<u16, ErrorReply<'static>> {
        if !self.standstill {
            return Err(ErrorReply::NotAtStandstill);
        }
        Ok(self.log.clear())
    }
    fn faults(&self) -> FaultReport {
        FaultReport {
            resets: 1,
            last_cause: 0,
            quick_resets: 0,
            uptime_ms: 10,
            latched: 0,
            active: 0,
            raised: 0,
        }
    }
    fn take_telemetry(&mut self) -> Option<Telemetry> {
        None
    }
    fn model_report(&self) -> ModelReport<'_> {
        ModelReport {
            enabled: true,
            updates: 3,
            gated: 0,
            failures: 0,
            params: Default::default(),
        }
    }
}

/// Bytes serialised as they are (postcard writes a tuple's elements without a length).
struct Raw<'a>(&'a [u8]);

impl serde::Serialize for Raw<'_> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeTuple;
        let mut t = s.serialize_tuple(self.0.len())?;
        for b in self.0 {
            t.serialize_element(b)?;
        }
        t.end()
    }
}

fuzz_target!(|data: &[u8]| {
    let Some((&sel, rest)) = data.split_first() else {
        return;
    };
    let mut stream = Vec::new();
    if sel % 2 == 0 {
        stream.extend_from_slice(rest);
        stream.push(0);
    } else {
        // A header (version and seq from the input when it asks for another version), then the
        // rest as the message, in as many frames as it takes.
        let (version, seq, body) = match rest {
            [v0, v1, s0, s1, body @ ..] if sel & 2 != 0 => (
                u16::from_le_bytes([*v0, *v1]),
                u16::from_le_bytes([*s0, *s1]),
                body,
            ),
            [s0, s1, body @ ..] => (PROTOCOL_VERSION, u16::from_le_bytes([*s0, *s1]), body),
            body => (PROTOCOL_VERSION, 1, body),
        };
        for chunk in body
            .chunks(MAX_PAYLOAD - 8)
            .chain(body.is_empty().then_some(&[][..]))
        {
            let mut f = [0u8; MAX_FRAME + 1];
            let n = frame::encode(Header { version, seq }, &Raw(chunk), &mut f)
                .expect("a chunk fits a frame");
            stream.extend_from_slice(&f[..n]);
        }
    }

    let mut reader = FrameReader::new();
    for &x in &stream {
        if let Fed::Frame(f) = reader.feed(x) {
            let (h, r) = decode_reply(f);
            if r.is_ok() {
                assert_eq!(
                    h.version, PROTOCOL_VERSION,
                    "a reply of another version was read"
                );
            }
        }
    }

    let mut log = RamLog::new();
    for t in 0..5 {
        log.append(LogEntry::Fault(FaultEvent {
            t_ms: t,
            kind: 1,
            latched: false,
        }));
    }
    let mut b = Ram {
        vehicle: Vehicle::nominal(),
        pending: false,
        standstill: sel & 4 != 0,
        log,
    };
    let mut dev = Device::new();
    let mut out = [0u8; REPLY_BYTES];
    let mut acknowledged = false;
    for &x in &stream {
        if let Some(n) = dev.on_byte(x, &mut b, &mut out) {
            assert!(n > 0 && out[n - 1] == 0, "a reply is one frame");
            let (h, r) = decode_reply(&mut out[..n - 1]);
            assert_eq!(h.version, PROTOCOL_VERSION);
            let r = r.unwrap_or_else(|e| panic!("the host cannot read the device's reply: {e}"));
            acknowledged |= matches!(r, Response::ConfigStored { .. } | Response::Cleared { .. });
        }
    }
    if !acknowledged {
        assert_eq!(
            b.vehicle,
            Vehicle::nominal(),
            "configuration changed without a reply"
        );
        assert_eq!(b.log.len(), (5, 0), "log changed without a reply");
    }
});

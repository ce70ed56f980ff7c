//! The device side: [`Device::on_byte`] turns received bytes into response frames over a
//! [`Backend`] that owns the state (configuration, event log, fault record, telemetry). It is
//! transport-independent: the firmware feeds it from a USART, the simulator's in-process device
//! from a byte queue, a test from a slice.
//!
//! Contract: every complete frame gets exactly one reply (a corrupted or unknown one an
//! [`ErrorReply`]); nothing the host sends can panic the handler or change the backend's state
//! unless it is a valid request (a configuration is decoded and validated whole by the core
//! before [`Backend::store_vehicle`] sees it).

use shimmy_core::vehicle::{decode_record, encode_record, RecordVehicle, RECORD_MAX_BYTES};

use crate::frame::{self, Fed, FrameError, FrameReader, MAX_FRAME};
use crate::log::Pager;
use crate::wire::{
    ConfigProblem, ErrorReply, EventPage, FaultReport, Header, Identity, ModelReport, Request,
    Response, Telemetry, PROTOCOL_HEADER,
};
use crate::PROTOCOL_VERSION;

/// The state behind the link. The firmware implements it on its RAM-held (later flash-held)
/// configuration and log; the simulator on its closed loop.
pub trait Backend {
    /// The vehicle it stores, as a record of its model (the car's `Vehicle`, the truck's
    /// `TruckVehicle`): a record of another model is refused for its schema id.
    type Vehicle: RecordVehicle;
    /// Firmware name and version, core version, log capacity.
    fn identity(&self) -> Identity<'_>;
    /// The stored vehicle configuration and whether it is still waiting for standstill.
    fn vehicle(&self) -> (&Self::Vehicle, bool);
    /// Stores a validated vehicle; returns whether it took effect at once (standstill) or waits
    /// for the next standstill.
    fn store_vehicle(&mut self, v: Self::Vehicle) -> bool;
    /// Reads the log front to back into `pager` (0 = oldest kept); returns the entries in it
    /// and the entries dropped because it was full.
    fn read_log(&mut self, pager: &mut Pager<'_>) -> Result<(u16, u32), ErrorReply<'static>>;
    /// Empties the log; returns the number of entries removed.
    fn clear_log(&mut self) -> Result<u16, ErrorReply<'static>>;
    /// The fault record.
    fn faults(&self) -> FaultReport;
    /// The newest margin report not handed out before, if any.
    fn take_telemetry(&mut self) -> Option<Telemetry>;
    /// The online model update's state.
    fn model_report(&self) -> ModelReport<'_>;
}

/// Largest reply of one request, bytes (one frame and its delimiter).
pub const REPLY_BYTES: usize = MAX_FRAME + 1;

/// The link's protocol state: the frame reader, the stream switch and the buffers.
pub struct Device {
    reader: FrameReader,
    streaming: bool,
    record: [u8; RECORD_MAX_BYTES],
}

impl Default for Device {
    fn default() -> Self {
        Self::new()
    }
}

impl Device {
    /// A device with the stream off.
    pub const fn new() -> Self {
        Device {
            reader: FrameReader::new(),
            streaming: false,
            record: [0; RECORD_MAX_BYTES],
        }
    }

    /// The telemetry stream is on.
    pub fn streaming(&self) -> bool {
        self.streaming
    }

    /// The handshake frame, sent once the port listens: [`Response::Ready`].
    pub fn ready<B: Backend>(backend: &B, out: &mut [u8; REPLY_BYTES]) -> usize {
        frame::encode(PROTOCOL_HEADER, &Response::Ready(backend.identity()), out).unwrap_or(0)
    }

    /// Drops a partial frame (the transport timed out in the middle of one).
    pub fn abandon_partial(&mut self) {
        self.reader.reset();
    }

    /// Feeds one received byte; when it completes a frame, writes the reply into `out` and
    /// returns its length.
    pub fn on_byte<B: Backend>(
        &mut self,
        byte: u8,
        backend: &mut B,
        out: &mut [u8; REPLY_BYTES],
    ) -> Option<usize> {
        let failure = match self.reader.feed(byte) {
            Fed::Pending => return None,
            Fed::TooLong => (0, ErrorReply::TooLong),
            Fed::Frame(f) => match frame::decode(f) {
                Err(e) => (0, ErrorReply::BadFrame(e.text())),
                Ok((h, _)) if h.version != PROTOCOL_VERSION => (
                    h.seq,
                    ErrorReply::Version {
                        device: PROTOCOL_VERSION,
                    },
                ),
                Ok((h, body)) => {
                    let h = Header {
                        seq: h.seq,
                        ..PROTOCOL_HEADER
                    };
                    return Some(Self::answer(
                        &mut self.streaming,
                        &mut self.record,
                        h,
                        body,
                        backend,
                        out,
                    ));
                }
            },
        };
        let (seq, e) = failure;
        let h = Header {
            seq,
            ..PROTOCOL_HEADER
        };
        Some(frame::encode(h, &Response::Error(e), out).unwrap_or(0))
    }

    /// When the stream is on and a new report is there: its frame in `out`.
    pub fn poll_stream<B: Backend>(
        &mut self,
        backend: &mut B,
        out: &mut [u8; REPLY_BYTES],
    ) -> Option<usize> {
        if !self.streaming {
            return None;
        }
        let t = backend.take_telemetry()?;
        frame::encode(PROTOCOL_HEADER, &Response::Telemetry(t), out).ok()
    }

    fn answer<B: Backend>(
        streaming: &mut bool,
        record: &mut [u8; RECORD_MAX_BYTES],
        h: Header,
        body: &[u8],
        backend: &mut B,
        out: &mut [u8; REPLY_BYTES],
    ) -> usize {
        let reply = match frame::message::<Request<'_>>(body) {
            None => Response::Error(ErrorReply::UnknownRequest),
            Some(req) => match req {
                Request::Identify => Response::Identity(backend.identity()),
                Request::GetConfig => {
                    let (v, pending) = backend.vehicle();
                    match encode_record(v, record) {
                        Ok(n) => Response::Config {
                            record: record.get(..n).unwrap_or_default(),
                            pending,
                        },
                        Err(e) => Response::Error(ErrorReply::Config(ConfigProblem::of(e))),
                    }
                }
                Request::SetConfig(bytes) => match decode_record::<B::Vehicle>(bytes) {
                    Ok(v) => Response::ConfigStored {
                        in_effect: backend.store_vehicle(v),
                    },
                    Err(e) => Response::Error(ErrorReply::Config(ConfigProblem::of(e))),
                },
                Request::ReadEvents { first } => {
                    let mut entries = heapless::Vec::new();
                    match backend.read_log(&mut Pager::new(first, &mut entries)) {
                        Err(e) => Response::Error(e),
                        Ok((kept, _)) if first > kept => {
                            Response::Error(ErrorReply::NoSuchEntry { kept })
                        }
                        Ok((kept, dropped)) => Response::Events(EventPage {
                            kept,
                            dropped,
                            first,
                            entries,
                        }),
                    }
                }
                Request::ClearEvents => match backend.clear_log() {
                    Ok(removed) => Response::Cleared { removed },
                    Err(e) => Response::Error(e),
                },
                Request::ReadFaults => Response::Faults(backend.faults()),
                Request::Telemetry { on } => {
                    *streaming = on;
                    Response::Streaming { on }
                }
                Request::ReadModel => Response::Model(backend.model_report()),
            },
        };
        frame::encode(h, &reply, out).unwrap_or_else(|_| {
            // Cannot happen for the bounded replies above (a test sends each); still a reply.
            frame::encode(
                h,
                &Response::Error(ErrorReply::BadFrame(FrameError::PayloadTooLong.text())),
                out,
            )
            .unwrap_or(0)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::{decode, encode, message};
    use crate::log::{EventSink, RamLog};
    use crate::wire::{FaultEvent, LogEntry, PROTOCOL_HEADER};
    use shimmy_core::vehicle::Vehicle;
    use std::vec::Vec;

    struct TestBackend {
        vehicle: Vehicle,
        moving: bool,
        pending: bool,
        log: RamLog<20>,
    }

    impl TestBackend {
        fn new() -> Self {
            let mut log = RamLog::new();
            for t in 0..12 {
                log.append(LogEntry::Fault(FaultEvent {
                    t_ms: t,
                    kind: 1,
                    latched: false,
                }));
            }
            TestBackend {
                vehicle: Vehicle::nominal(),
                moving: true,
                pending: false,
                log,
            }
        }
    }

    impl Backend for TestBackend {
        type Vehicle = Vehicle;
        fn identity(&self) -> Identity<'_> {
            Identity {
                firmware: "test",
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
            self.pending = self.moving;
            !self.moving
        }
        fn read_log(&mut self, pager: &mut Pager<'_>) -> Result<(u16, u32), ErrorReply<'static>> {
            Ok(self.log.page(None, pager))
        }
        fn clear_log(&mut self) -> Result<u16, ErrorReply<'static>> {
            if self.moving {
                return Err(ErrorReply::NotAtStandstill);
            }
            Ok(self.log.clear())
        }
        fn faults(&self) -> FaultReport {
            FaultReport {
                resets: 2,
                last_cause: 1,
                quick_resets: 0,
                uptime_ms: 5,
                latched: 0,
                active: 0,
                raised: 3,
            }
        }
        fn take_telemetry(&mut self) -> Option<Telemetry> {
            None
        }
        fn model_report(&self) -> ModelReport<'_> {
            test_model_report()
        }
    }

    /// A full model report with the longest names a model has (the car's, every one out of
    /// its band).
    fn test_model_report() -> ModelReport<'static> {
        use shimmy_core::model::UpdatableModel;
        use shimmy_core::vehicles::car::PlantParams;
        let params = PlantParams::UPDATE_PARAMS
            .iter()
            .map(|u| crate::wire::ParamReport {
                field: u.field,
                what: u.what,
                factor: 0.5,
                sigma_ln: 0.02,
                band_low: u.band.0 as f32,
                band_high: u.band.1 as f32,
                out_of_band: true,
            })
            .collect();
        ModelReport {
            enabled: true,
            updates: 600,
            gated: 3,
            failures: 0,
            params,
        }
    }

    /// Feeds `bytes`; returns the decoded replies (header and message bytes).
    fn feed(dev: &mut Device, b: &mut TestBackend, bytes: &[u8]) -> Vec<(Header, Vec<u8>)> {
        let mut out = [0u8; REPLY_BYTES];
        let mut replies = Vec::new();
        for &x in bytes {
            if let Some(n) = dev.on_byte(x, b, &mut out) {
                assert!(n > 0 && out[n - 1] == 0, "a reply frame");
                let (h, m) = decode(&mut out[..n - 1]).expect("device replies are valid frames");
                replies.push((h, m.to_vec()));
            }
        }
        replies
    }

    fn request_bytes(seq: u16, r: &Request<'_>) -> Vec<u8> {
        let mut out = [0u8; MAX_FRAME + 1];
        let n = encode(
            Header {
                seq,
                ..PROTOCOL_HEADER
            },
            r,
            &mut out,
        )
        .unwrap();
        out[..n].to_vec()
    }

    fn one_reply(dev: &mut Device, b: &mut TestBackend, bytes: &[u8]) -> (u16, Response<'static>) {
        let mut r = feed(dev, b, bytes);
        assert_eq!(r.len(), 1, "exactly one reply");
        let (h, m) = r.remove(0);
        let m: &'static [u8] = std::boxed::Box::leak(m.into_boxed_slice());
        (h.seq, message::<Response<'_>>(m).expect("a known response"))
    }

    fn record(v: &Vehicle) -> Vec<u8> {
        let mut buf = [0u8; RECORD_MAX_BYTES];
        let n = v.encode_record(&mut buf).unwrap();
        buf[..n].to_vec()
    }

    fn other_vehicle() -> Vehicle {
        let mut v = Vehicle::nominal();
        v.set("plant", "k_d", 4321.0).unwrap();
        v
    }

    #[test]
    fn identity_config_round_trip_and_events_paging() {
        let (mut dev, mut b) = (Device::new(), TestBackend::new());
        let (seq, r) = one_reply(&mut dev, &mut b, &request_bytes(5, &Request::Identify));
        assert_eq!(seq, 5);
        assert!(matches!(r, Response::Identity(i) if i.firmware == "test"));
        let rec = record(&other_vehicle());
        let (_, r) = one_reply(
            &mut dev,
            &mut b,
            &request_bytes(6, &Request::SetConfig(&rec)),
        );
        assert_eq!(
            r,
            Response::ConfigStored { in_effect: false },
            "moving: pending"
        );
        let (_, r) = one_reply(&mut dev, &mut b, &request_bytes(7, &Request::GetConfig));
        let Response::Config {
            record: got,
            pending,
        } = r
        else {
            panic!("{r:?}")
        };
        assert!(pending);
        assert_eq!(got, rec.as_slice(), "read back identical");
        // Paging: 12 entries in pages of 8.
        let (_, r) = one_reply(
            &mut dev,
            &mut b,
            &request_bytes(8, &Request::ReadEvents { first: 8 }),
        );
        let Response::Events(p) = r else {
            panic!("{r:?}")
        };
        assert_eq!((p.kept, p.first, p.entries.len()), (12, 8, 4));
        let (_, r) = one_reply(
            &mut dev,
            &mut b,
            &request_bytes(9, &Request::ReadEvents { first: 13 }),
        );
        assert_eq!(r, Response::Error(ErrorReply::NoSuchEntry { kept: 12 }));
        // Moving: the clear (an erase) is refused and the log stays.
        let (_, r) = one_reply(&mut dev, &mut b, &request_bytes(10, &Request::ClearEvents));
        assert_eq!(r, Response::Error(ErrorReply::NotAtStandstill));
        assert_eq!(b.log.len(), (12, 0));
        b.moving = false;
        let (_, r) = one_reply(&mut dev, &mut b, &request_bytes(11, &Request::ClearEvents));
        assert_eq!(r, Response::Cleared { removed: 12 });
    }

    fn assert_intact(b: &TestBackend) {
        assert_eq!(b.vehicle, Vehicle::nominal(), "configuration unchanged");
        assert_eq!(b.log.len(), (12, 0), "log unchanged");
    }

    /// The model report of a full update set fits a frame and arrives whole.
    #[test]
    fn the_model_report_arrives_whole() {
        let (mut dev, mut b) = (Device::new(), TestBackend::new());
        let (seq, r) = one_reply(&mut dev, &mut b, &request_bytes(9, &Request::ReadModel));
        assert_eq!(seq, 9);
        let Response::Model(m) = r else {
            panic!("{r:?}")
        };
        assert_eq!(m, test_model_report());
        assert_eq!(m.params.len(), 5);
    }

    #[test]
    fn a_corrupted_frame_gets_an_error_and_changes_nothing() {
        let (mut dev, mut b) = (Device::new(), TestBackend::new());
        let rec = record(&other_vehicle());
        let mut bytes = request_bytes(3, &Request::SetConfig(&rec));
        bytes[40] ^= 0x10;
        let (seq, r) = one_reply(&mut dev, &mut b, &bytes);
        assert_eq!(seq, 0, "no trusted seq in a corrupted frame");
        assert!(
            matches!(r, Response::Error(ErrorReply::BadFrame(_))),
            "{r:?}"
        );
        assert_intact(&b);
    }

    #[test]
    fn a_frame_too_long_gets_an_error_and_changes_nothing() {
        let (mut dev, mut b) = (Device::new(), TestBackend::new());
        let mut bytes = std::vec![0x11u8; MAX_FRAME + 1];
        bytes.push(0);
        let (_, r) = one_reply(&mut dev, &mut b, &bytes);
        assert_eq!(r, Response::Error(ErrorReply::TooLong));
        assert_intact(&b);
        // The device listens again at once.
        let (seq, r) = one_reply(&mut dev, &mut b, &request_bytes(4, &Request::ReadFaults));
        assert_eq!(seq, 4);
        assert!(matches!(r, Response::Faults(_)));
    }

    #[test]
    fn an_unknown_request_or_version_gets_an_error() {
        let (mut dev, mut b) = (Device::new(), TestBackend::new());
        // A well-formed frame whose request kind is beyond the known ones (a newer host).
        let mut out = [0u8; MAX_FRAME + 1];
        let n = encode(
            Header {
                seq: 9,
                ..PROTOCOL_HEADER
            },
            &(42u8, 1u8),
            &mut out,
        )
        .unwrap();
        let (seq, r) = one_reply(&mut dev, &mut b, &out[..n]);
        assert_eq!((seq, r), (9, Response::Error(ErrorReply::UnknownRequest)));
        let n = encode(
            Header {
                version: 99,
                seq: 10,
            },
            &Request::ClearEvents,
            &mut out,
        )
        .unwrap();
        let (seq, r) = one_reply(&mut dev, &mut b, &out[..n]);
        assert_eq!(seq, 10);
        assert_eq!(
            r,
            Response::Error(ErrorReply::Version {
                device: PROTOCOL_VERSION
            })
        );
        assert_intact(&b);
    }

    #[test]
    fn a_configuration_out_of_range_is_refused_naming_the_field() {
        let (mut dev, mut b) = (Device::new(), TestBackend::new());
        let mut rec = record(&Vehicle::nominal());
        let f = shimmy_core::vehicle::find_field("plant", "k_d").unwrap();
        let i = shimmy_core::vehicle::FIELDS
            .iter()
            .position(|x| core::ptr::eq(x, f))
            .unwrap();
        let at = shimmy_core::vehicle::RECORD_HEADER_BYTES + 8 * i;
        rec[at..at + 8].copy_from_slice(&(f.hi * 10.0).to_le_bytes());
        let (_, r) = one_reply(
            &mut dev,
            &mut b,
            &request_bytes(2, &Request::SetConfig(&rec)),
        );
        let Response::Error(ErrorReply::Config(ConfigProblem::Field {
            section,
            name,
            value,
            ..
        })) = r
        else {
            panic!("{r:?}")
        };
        assert_eq!((section, name, value), ("plant", "k_d", f.hi * 10.0));
        // A truncated record too.
        let (_, r) = one_reply(
            &mut dev,
            &mut b,
            &request_bytes(3, &Request::SetConfig(&rec[..20])),
        );
        assert!(matches!(
            r,
            Response::Error(ErrorReply::Config(ConfigProblem::Length { .. }))
        ));
        assert_intact(&b);
    }

    #[test]
    fn a_link_unplugged_mid_transfer_changes_nothing_and_the_next_request_works() {
        let (mut dev, mut b) = (Device::new(), TestBackend::new());
        let rec = record(&other_vehicle());
        let bytes = request_bytes(3, &Request::SetConfig(&rec));
        // Half the frame, then nothing: no reply, nothing stored.
        assert!(feed(&mut dev, &mut b, &bytes[..bytes.len() / 2]).is_empty());
        assert_intact(&b);
        // The transport's timeout drops the partial frame; a new request is answered.
        dev.abandon_partial();
        let (seq, _) = one_reply(&mut dev, &mut b, &request_bytes(4, &Request::Identify));
        assert_eq!(seq, 4);
        // Without the timeout, the next frame's bytes join the stale half: an error, still
        // nothing stored, and the request after it is answered.
        assert!(feed(&mut dev, &mut b, &bytes[..bytes.len() / 2]).is_empty());
        let (_, r) = one_reply(&mut dev, &mut b, &request_bytes(5, &Request::Identify));
        assert!(matches!(r, Response::Error(_)), "{r:?}");
        assert_intact(&b);
        let (seq, _) = one_reply(&mut dev, &mut b, &request_bytes(6, &Request::Identify));
        assert_eq!(seq, 6);
    }

    #[test]
    fn the_stream_sends_only_when_on() {
        let (mut dev, mut b) = (Device::new(), TestBackend::new());
        let mut out = [0u8; REPLY_BYTES];
        assert!(dev.poll_stream(&mut b, &mut out).is_none());
        let (_, r) = one_reply(
            &mut dev,
            &mut b,
            &request_bytes(1, &Request::Telemetry { on: true }),
        );
        assert_eq!(r, Response::Streaming { on: true });
        assert!(dev.streaming());
        let n = Device::ready(&b, &mut out);
        let (h, m) = decode(&mut out[..n - 1]).unwrap();
        assert_eq!(h.seq, 0);
        assert!(matches!(
            message::<Response<'_>>(m),
            Some(Response::Ready(_))
        ));
    }

    /// Deterministic pseudo-random numbers (xorshift64*), so a failure replays.
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
        }
        fn below(&mut self, n: usize) -> usize {
            (self.next() % n as u64) as usize
        }
    }

    /// Bytes serialised as they are (postcard writes a tuple's elements without a length):
    /// a random message behind a valid header and CRC, which random bytes alone almost never
    /// reach.
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

    /// Random bytes, and random messages in valid frames of this and other versions, into the
    /// host's decoder and the device's handler: no panic; the decoder reads only replies of
    /// this version; the handler answers every frame with a reply of this version that the
    /// host reads, and changes the backend only for a request it acknowledged.
    #[test]
    fn random_frames_get_clean_errors_from_the_host_decoder_and_the_handler() {
        use crate::frame::{FrameReader, MAX_PAYLOAD};
        use crate::host::decode_reply;
        let mut rng = Rng(0x5eed_1234_abcd_0001);
        let (mut dev, mut b) = (Device::new(), TestBackend::new());
        let mut out = [0u8; REPLY_BYTES];
        let (mut frames, mut replies, mut read_ok) = (0, 0, 0);
        for case in 0..20_000 {
            let len = rng.below(MAX_PAYLOAD + 64);
            let mut body: Vec<u8> = (0..len).map(|_| rng.next() as u8).collect();
            // Mostly a known message kind first (the enums' first byte), so the fields behind
            // it are read too.
            if let Some(kind) = body.first_mut().filter(|_| case % 4 == 1) {
                *kind = rng.below(12) as u8;
            }
            let stream = if case % 2 == 0 {
                let mut s = body;
                s.push(0);
                s
            } else {
                let version = match rng.below(4) {
                    0 => rng.next() as u16,
                    _ => PROTOCOL_VERSION,
                };
                let h = Header {
                    version,
                    seq: rng.next() as u16,
                };
                let mut f = [0u8; MAX_FRAME + 1];
                let n = encode(h, &Raw(&body[..len.min(MAX_PAYLOAD - 8)]), &mut f)
                    .expect("fits a frame");
                f[..n].to_vec()
            };
            let mut reader = FrameReader::new();
            for &x in &stream {
                if let crate::frame::Fed::Frame(f) = reader.feed(x) {
                    frames += 1;
                    let (h, r) = decode_reply(f);
                    if r.is_ok() {
                        read_ok += 1;
                        assert_eq!(h.version, PROTOCOL_VERSION, "case {case}");
                    }
                }
            }
            let before = (b.vehicle, b.log.len());
            let mut acknowledged = false;
            for &x in &stream {
                if let Some(n) = dev.on_byte(x, &mut b, &mut out) {
                    replies += 1;
                    assert!(n > 0 && out[n - 1] == 0, "case {case}: a reply frame");
                    let (h, r) = decode_reply(&mut out[..n - 1]);
                    assert_eq!(h.version, PROTOCOL_VERSION, "case {case}");
                    let r = r.unwrap_or_else(|e| panic!("case {case}: unreadable reply: {e}"));
                    acknowledged |=
                        matches!(r, Response::ConfigStored { .. } | Response::Cleared { .. });
                }
            }
            if !acknowledged {
                assert_eq!((b.vehicle, b.log.len()), before, "case {case}");
            }
        }
        // The cases reached every stage: frames, replies, and messages past the CRC.
        assert!(
            frames > 20_000 && replies > 20_000 && read_ok > 300,
            "{frames} {replies} {read_ok}"
        );
    }
}

//! The host link end to end on the in-process simulated device (the link's own handler on the
//! simulator's closed loop): the normal flow, and bad input of each kind -- a corrupted frame, a
//! frame too long, an unknown request, a configuration out of range, a link unplugged in the
//! middle of a transfer -- each giving a clear error on the host and leaving the device's
//! configuration and log as they were.

use anyhow::Result;
use shimmy_core::vehicle::{
    encode_record, find_field, record_index, record_schema_of, Vehicle, FIELDS,
    RECORD_HEADER_BYTES, RECORD_MAX_BYTES,
};
use shimmy_core::vehicles::truck::board::TruckVehicle;
use shimmy_core::vehicles::truck::TruckParams;
use shimmy_link::frame::{self, MAX_FRAME};
use shimmy_link::wire::{
    ErrorReply, FaultReport, Header, Identity, LogEntry, Response, Telemetry, PROTOCOL_HEADER,
};
use shimmy_link::PROTOCOL_VERSION;
use shimmy_sim::model::board::BoardModel;
use shimmy_sim::model::family::FamilyVehicle;
use shimmy_sim::sim::device::device_link::{read_record, Client, DeviceInfo, Port};
use shimmy_sim::sim::device::sim_device::{SimDevice, PARITY_FAULT_S};
use shimmy_sim::sim::input::vehicle_file::{self, ModelVehicle};
use std::time::Duration;

/// What can go wrong on the way to the device.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Trouble {
    None,
    /// The byte at this offset of the next request arrives with a bit flipped.
    Flip(usize),
    /// The cable is pulled after this many bytes of the next request: the rest never arrives.
    Unplug(usize),
}

/// The simulated device behind a line that can damage or cut the next request.
struct Line {
    dev: SimDevice,
    trouble: Trouble,
    unplugged: bool,
}

impl Port for Line {
    fn send(&mut self, bytes: &[u8]) -> Result<()> {
        match std::mem::replace(&mut self.trouble, Trouble::None) {
            Trouble::None if !self.unplugged => self.dev.send(bytes),
            Trouble::None => Ok(()),
            Trouble::Flip(i) => {
                let mut b = bytes.to_vec();
                b[i] ^= 0x08;
                self.dev.send(&b)
            }
            Trouble::Unplug(n) => {
                self.unplugged = true;
                self.dev.send(&bytes[..n])
            }
        }
    }
    fn receive(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize> {
        if self.unplugged {
            std::thread::sleep(timeout.min(Duration::from_millis(5)));
            return Ok(0);
        }
        self.dev.receive(buf, timeout)
    }
}

/// A fresh simulated device (its drive takes well under a second) behind a healthy line.
fn device() -> Client<Line> {
    let dev = SimDevice::new(&FamilyVehicle::car(Vehicle::nominal())).expect("simulated drive");
    let line = Line {
        dev,
        trouble: Trouble::None,
        unplugged: false,
    };
    let (mut c, info) = Client::connect(line, Duration::from_millis(100)).expect("ready frame");
    assert!(info.firmware.contains("in-process device"));
    c.set_timeout(Duration::from_millis(300));
    c
}

/// The device's configuration and log, to show that bad input left them alone.
fn state(c: &mut Client<Line>) -> (Vec<u64>, (u16, u32)) {
    let b = c.port_mut().dev.backend();
    let v = b.stored_vehicle();
    (
        FIELDS.iter().map(|f| v.get(f).to_bits()).collect(),
        b.logged(),
    )
}

fn another_vehicle() -> Vehicle {
    let mut v = Vehicle::nominal();
    v.set("plant", "k_d", 4321.5).unwrap();
    v
}

#[test]
fn the_simulated_drive_logs_its_shimmy_episode_and_its_fault_and_config_round_trips() {
    let mut c = device();
    let log = c.events().unwrap();
    let shimmy: Vec<_> = log
        .entries
        .iter()
        .filter_map(|e| match e {
            LogEntry::Shimmy(s) => Some(*s),
            LogEntry::Fault(_) | LogEntry::Boot(_) | LogEntry::Diagnosis(_) => None,
        })
        .collect();
    assert!(!shimmy.is_empty(), "a warning episode in {log:?}");
    assert!(
        matches!(log.entries.first(), Some(LogEntry::Boot(_))),
        "the log starts with the boot, as a board's: {log:?}"
    );
    assert!(shimmy.iter().all(|s| s.peak_current_a.is_finite()));
    let fault_ms: Vec<u32> = log
        .entries
        .iter()
        .filter_map(|e| match e {
            LogEntry::Fault(f) => Some(f.t_ms),
            LogEntry::Shimmy(_) | LogEntry::Boot(_) | LogEntry::Diagnosis(_) => None,
        })
        .collect();
    let start_ms = (PARITY_FAULT_S.0 * 1e3) as u32;
    assert!(
        fault_ms
            .iter()
            .any(|&t| (start_ms..start_ms + 20).contains(&t)),
        "the injected parity fault at {} s is in the log: {fault_ms:?}",
        PARITY_FAULT_S.0
    );
    let f = c.faults().unwrap();
    assert!(f.raised >= 1 && f.active == 0, "{f:?}");
    // The drive ended at standstill: a new configuration is in effect at once.
    let v = another_vehicle();
    assert!(c.set_config(&v).unwrap(), "in effect at standstill");
    let (back, pending) = c.config().unwrap();
    assert!(!pending);
    for f in FIELDS {
        assert_eq!(
            back.get(f).to_bits(),
            v.get(f).to_bits(),
            "{}.{}",
            f.section(),
            f.name
        );
    }
    // ... and through the vehicle file writer and reader, bit for bit.
    let reread = vehicle_file::parse(&vehicle_file::to_toml(&back)).unwrap();
    assert_eq!(reread, v);
}

#[test]
fn a_corrupted_frame_is_reported_and_changes_nothing() {
    let mut c = device();
    let before = state(&mut c);
    // Byte 30 of the frame lies inside the vehicle record.
    c.port_mut().trouble = Trouble::Flip(30);
    let e = c.set_config(&another_vehicle()).unwrap_err().to_string();
    assert!(e.contains("damaged frame") && e.contains("CRC"), "{e}");
    assert_eq!(state(&mut c), before);
    // Without the damage the same request goes through: the check above depends on it.
    assert!(c.set_config(&another_vehicle()).is_ok());
    assert_ne!(state(&mut c).0, before.0);
}

#[test]
fn a_frame_too_long_is_reported_and_changes_nothing() {
    let mut c = device();
    let before = state(&mut c);
    let e = c
        .send_raw(&vec![0x42u8; MAX_FRAME + 1])
        .unwrap_err()
        .to_string();
    assert!(e.contains("longer than") && e.contains("dropped"), "{e}");
    assert_eq!(state(&mut c), before);
    // The host's own bound: a record too large for a frame is not sent at all.
    let e = c
        .set_record(&vec![1u8; 2 * RECORD_MAX_BYTES])
        .unwrap_err()
        .to_string();
    assert!(e.contains("not sent"), "{e}");
    assert_eq!(state(&mut c), before);
    assert!(c.info().is_ok(), "the device listens on");
}

#[test]
fn an_unknown_request_is_reported_and_changes_nothing() {
    let mut c = device();
    let before = state(&mut c);
    // A well-formed frame whose request kind this protocol version does not have.
    let h = Header {
        seq: 77,
        ..PROTOCOL_HEADER
    };
    let mut out = vec![0u8; MAX_FRAME + 1];
    let n = frame::encode(h, &(200u8, 0u8), &mut out).unwrap();
    let e = c.send_raw(&out[..n - 1]).unwrap_err().to_string();
    assert!(e.contains("does not know this request"), "{e}");
    // Another protocol version.
    let h = Header {
        version: 9,
        seq: 78,
    };
    let n = frame::encode(h, &(0u8,), &mut out).unwrap();
    let e = c.send_raw(&out[..n - 1]).unwrap_err().to_string();
    assert!(
        e.contains("version mismatch") && e.contains(&format!("speaks version {PROTOCOL_VERSION}")),
        "{e}"
    );
    assert_eq!(state(&mut c), before);
}

#[test]
fn a_configuration_out_of_range_is_refused_naming_the_field_and_its_range() {
    let mut c = device();
    let before = state(&mut c);
    let f = find_field("plant", "k_d").unwrap();
    let i = FIELDS.iter().position(|x| std::ptr::eq(x, f)).unwrap();
    let mut rec = [0u8; RECORD_MAX_BYTES];
    let n = Vehicle::nominal().encode_record(&mut rec).unwrap();
    let at = RECORD_HEADER_BYTES + 8 * i;
    rec[at..at + 8].copy_from_slice(&(f.hi * 2.0).to_le_bytes());
    let e = c.set_record(&rec[..n]).unwrap_err().to_string();
    assert!(
        e.contains("refused the configuration")
            && e.contains("plant.k_d")
            && e.contains(&format!("{}", f.hi)),
        "{e}"
    );
    // A rule between fields, checked on the device too.
    let mut v = Vehicle::nominal();
    v.controller.asmc.k_init_radps2 = v.controller.asmc.k_max_radps2 * 2.0;
    let n = v.encode_record(&mut rec).unwrap();
    let e = c.set_record(&rec[..n]).unwrap_err().to_string();
    assert!(
        e.contains("k_init_radps2") && e.contains("must lie between"),
        "{e}"
    );
    // The host validates first: the same vehicle is never sent.
    assert!(c.set_config(&v).is_err());
    assert_eq!(state(&mut c), before);
}

#[test]
fn a_link_unplugged_mid_transfer_is_reported_and_changes_nothing() {
    let mut c = device();
    let before = state(&mut c);
    c.port_mut().trouble = Trouble::Unplug(200);
    let e = c.set_config(&another_vehicle()).unwrap_err().to_string();
    assert!(
        e.contains("no reply from the device") && e.contains("unplugged"),
        "{e}"
    );
    assert_eq!(state(&mut c), before, "half a record stored nothing");
    // Plugged in again: the half frame left in the device is ended by the next request's
    // leading delimiter, and the request is answered.
    c.port_mut().unplugged = false;
    assert!(c.info().is_ok());
    assert_eq!(state(&mut c), before);
    let n = c.events().unwrap().entries.len();
    assert!(n > 0);
}

/// The command line: a vehicle file out of range is refused by the tool before anything is
/// sent (non-zero exit, the field and its allowed range named), and a device command without a
/// place says which places there are.
#[test]
fn the_tool_refuses_a_bad_vehicle_file_and_a_missing_device() {
    let dir = std::env::temp_dir().join(format!("shimmy-device-link-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bad = dir.join("bad.toml");
    std::fs::write(&bad, "[plant]\nk_d = 1e12\n").unwrap();
    let tool = env!("CARGO_BIN_EXE_shimmy-sim");
    let o = std::process::Command::new(tool)
        .args(["device", "--sim", "config", "set"])
        .arg(&bad)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("plant.k_d") && err.contains("allowed"),
        "{err}"
    );
    assert!(!String::from_utf8_lossy(&o.stdout).contains("stored"));
    let o = std::process::Command::new(tool)
        .args(["device", "info"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("--serial PORT, --tcp HOST:PORT or --sim"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// A simulated device that stores trucks, behind a healthy line.
fn truck_device() -> (
    Client<shimmy_sim::sim::device::sim_device::SimDevice<TruckVehicle>>,
    DeviceInfo,
) {
    let ModelVehicle::Truck(t) = vehicle_file::load_model("truck-full").unwrap() else {
        panic!("truck-full is a truck")
    };
    let dev = SimDevice::new(&t).expect("simulated truck drive");
    let (mut c, info) = Client::connect(dev, Duration::from_millis(100)).expect("ready frame");
    c.set_timeout(Duration::from_millis(300));
    (c, info)
}

/// A truck vehicle file goes to a truck device and comes back bit for bit (through the record
/// and the vehicle-file writer and reader), its record under the truck's own schema id.
#[test]
fn a_truck_vehicle_round_trips_through_a_truck_device() {
    let (mut c, info) = truck_device();
    assert_eq!(info.vehicle_schema, record_schema_of::<TruckVehicle>());
    assert_ne!(info.vehicle_schema, record_schema_of::<Vehicle>());
    let text =
        "model = \"mining-truck-5dof\"\nbase = \"truck-empty\"\n[truck]\nhps_v0_m3 = 0.0145\n\
                payload_kg = 100000\n[controller]\nslew_a_per_s = 123.0\n";
    let ModelVehicle::Truck(t) = vehicle_file::parse_model(text).unwrap() else {
        panic!("a truck file")
    };
    let sent = TruckParams::board_vehicle(&t);
    assert!(c.set_config(&sent).unwrap(), "in effect at standstill");
    let (rec, pending) = c.config_record().unwrap();
    assert!(!pending);
    let back: TruckVehicle = read_record(&rec).unwrap();
    assert_eq!(back.truck, sent.truck);
    assert_eq!(back.truck.payload_kg, 100_000.0);
    assert_eq!(back.parts.controller.slew_a_per_s, 123.0);
    assert_eq!(*c.port_mut().backend().stored_vehicle(), back);
    // ... and through the vehicle file writer and reader, bit for bit.
    let file = vehicle_file::model_to_toml::<TruckParams, { shimmy_core::vehicles::truck::N_STATES }>(
        &TruckParams::from_board(&back),
    );
    let ModelVehicle::Truck(reread) = vehicle_file::parse_model(&file).unwrap() else {
        panic!("the written file reads as a truck: {file}")
    };
    assert_eq!(reread, t);
}

/// A car vehicle sent to a truck device, and a truck vehicle to a car device, are refused by
/// the device naming both models; nothing is stored. A truck value out of range is refused
/// naming the field and its range.
#[test]
fn a_vehicle_of_the_other_model_is_refused_naming_both_models() {
    let (mut c, _) = truck_device();
    let before = *c.port_mut().backend().stored_vehicle();
    let e = c.set_config(&Vehicle::nominal()).unwrap_err().to_string();
    assert!(
        e.contains("refused")
            && e.contains("is a car-4dof vehicle")
            && e.contains("stores mining-truck-5dof vehicles"),
        "{e}"
    );
    assert_eq!(*c.port_mut().backend().stored_vehicle(), before);
    // a truck field far out of its range, in a truck record
    let mut rec = [0u8; RECORD_MAX_BYTES];
    let n = encode_record(&before, &mut rec).unwrap();
    let i = record_index::<TruckVehicle>("truck", "hps_v0_m3").unwrap();
    let at = RECORD_HEADER_BYTES + 8 * i;
    rec[at..at + 8].copy_from_slice(&5.0f64.to_le_bytes());
    let e = c.set_record(&rec[..n]).unwrap_err().to_string();
    assert!(e.contains("truck.hps_v0_m3") && e.contains("0.2"), "{e}");
    assert_eq!(*c.port_mut().backend().stored_vehicle(), before);

    let mut car = device();
    let before = state(&mut car);
    let e = car.set_config(&before_truck()).unwrap_err().to_string();
    assert!(
        e.contains("is a mining-truck-5dof vehicle") && e.contains("stores car-4dof vehicles"),
        "{e}"
    );
    assert_eq!(state(&mut car), before);
    // the car's reader names the truck record it cannot read
    let n = encode_record(&before_truck(), &mut rec).unwrap();
    let e = read_record::<Vehicle>(&rec[..n]).unwrap_err().to_string();
    assert!(e.contains("mining-truck-5dof"), "{e}");
}

fn before_truck() -> TruckVehicle {
    let ModelVehicle::Truck(t) = vehicle_file::load_model("truck-full").unwrap() else {
        panic!("truck-full is a truck")
    };
    TruckParams::board_vehicle(&t)
}

/// The command line with a truck device: `config get` writes a truck vehicle file, `config
/// set` of a truck file is stored and read back, a car file is refused before anything is sent.
#[test]
fn the_tool_gets_and_sets_a_truck_vehicle_file() {
    let dir = std::env::temp_dir().join(format!("shimmy-device-truck-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let tool = env!("CARGO_BIN_EXE_shimmy-sim");
    let got = dir.join("got.toml");
    let o = std::process::Command::new(tool)
        .args([
            "device",
            "--sim",
            "--vehicle",
            "truck-full",
            "config",
            "get",
            "--out",
        ])
        .arg(&got)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = std::fs::read_to_string(&got).unwrap();
    assert!(text.contains("model = \"mining-truck-5dof\"") && text.contains("[truck]"));
    assert!(text.contains("payload_kg = 227000.0"), "{text}");
    let set = dir.join("set.toml");
    std::fs::write(
        &set,
        text.replace("payload_kg = 227000.0", "payload_kg = 150000.0"),
    )
    .unwrap();
    let o = std::process::Command::new(tool)
        .args([
            "device",
            "--sim",
            "--vehicle",
            "truck-full",
            "config",
            "set",
        ])
        .arg(&set)
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.contains("read back identical (98 fields)"), "{out}");
    let o = std::process::Command::new(tool)
        .args([
            "device",
            "--sim",
            "--vehicle",
            "truck-full",
            "config",
            "set",
            "nominal",
        ])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("nothing sent")
            && err.contains("car-4dof")
            && err.contains("mining-truck-5dof"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// A device that answers each request with the frame `answer` makes for its seq: replies no
/// firmware of this version would send.
struct Scripted<F: FnMut(u16) -> Vec<u8>> {
    answer: F,
    reader: frame::FrameReader,
    out: std::collections::VecDeque<u8>,
}

impl<F: FnMut(u16) -> Vec<u8>> Scripted<F> {
    fn new(answer: F) -> Self {
        Scripted {
            answer,
            reader: frame::FrameReader::new(),
            out: Default::default(),
        }
    }
}

impl<F: FnMut(u16) -> Vec<u8>> Port for Scripted<F> {
    fn send(&mut self, bytes: &[u8]) -> Result<()> {
        for &b in bytes {
            if let frame::Fed::Frame(f) = self.reader.feed(b) {
                let (h, _) = frame::decode(f).expect("the client sends valid frames");
                let reply = (self.answer)(h.seq);
                self.out.extend(reply);
            }
        }
        Ok(())
    }
    fn receive(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize> {
        if self.out.is_empty() {
            std::thread::sleep(timeout.min(Duration::from_millis(1)));
        }
        let n = buf.len().min(self.out.len());
        for (b, x) in buf.iter_mut().zip(self.out.drain(..n)) {
            *b = x;
        }
        Ok(n)
    }
}

fn reply_frame(h: Header, r: &Response<'_>) -> Vec<u8> {
    let mut out = vec![0u8; MAX_FRAME + 1];
    let n = frame::encode(h, r, &mut out).unwrap();
    out.truncate(n);
    out
}

fn identity(firmware: &str) -> Identity<'_> {
    Identity {
        firmware,
        core: "core",
        protocol: PROTOCOL_VERSION,
        vehicle_schema: record_schema_of::<Vehicle>(),
        log_capacity: 8,
    }
}

#[test]
fn a_reply_of_another_protocol_version_is_refused_naming_both_versions() {
    // The frame's header says another version; its identity claims this one.
    let other = PROTOCOL_VERSION + 1;
    let port = Scripted::new(|seq| {
        reply_frame(
            Header {
                version: other,
                seq,
            },
            &Response::Identity(identity("fw")),
        )
    });
    let e = match Client::connect(port, Duration::ZERO) {
        Ok((_, info)) => panic!("a reply of protocol version {other} was accepted: {info:?}"),
        Err(e) => e.to_string(),
    };
    assert!(
        e.contains(&format!("protocol version {other}"))
            && e.contains(&format!("supports version {PROTOCOL_VERSION}")),
        "{e}"
    );
}

/// A telemetry sample at `t_s`.
fn sample(t_s: f64) -> Telemetry {
    Telemetry {
        t_s,
        speed_mps: 20.0,
        zeta_data: 0.05,
        sigma_zeta_data: 0.01,
        zeta_fast: 0.05,
        freq_hz: 6.0,
        zeta_model: 0.04,
        speed_margin_mps: 3.0,
        level: 0,
        valid: true,
    }
}

/// Past the handshake too, every frame is read through the version check: a later reply of
/// another version is refused naming both versions, and a telemetry sample of another version
/// in the stream is skipped (the next one of this version is the first read).
#[test]
fn a_later_reply_or_sample_of_another_version_is_refused() {
    let other = PROTOCOL_VERSION + 1;
    let port = Scripted::new(move |seq| {
        let this = Header {
            seq,
            ..PROTOCOL_HEADER
        };
        let theirs = Header {
            version: other,
            seq,
        };
        match seq {
            1 => reply_frame(this, &Response::Identity(identity("fw"))),
            2 => reply_frame(
                theirs,
                &Response::Faults(FaultReport {
                    resets: 1,
                    last_cause: 0,
                    quick_resets: 0,
                    uptime_ms: 10,
                    latched: 0,
                    active: 0,
                    raised: 0,
                }),
            ),
            _ => [
                reply_frame(this, &Response::Streaming { on: true }),
                reply_frame(
                    Header { seq: 0, ..theirs },
                    &Response::Telemetry(sample(1.0)),
                ),
                reply_frame(Header { seq: 0, ..this }, &Response::Telemetry(sample(2.0))),
            ]
            .concat(),
        }
    });
    let (mut c, _) = Client::connect(port, Duration::ZERO).expect("identity");
    let e = match c.faults() {
        Ok(f) => panic!("a fault record of protocol version {other} was read: {f:?}"),
        Err(e) => e.to_string(),
    };
    assert!(
        e.contains(&format!("protocol version {other}"))
            && e.contains(&format!("supports version {PROTOCOL_VERSION}")),
        "{e}"
    );
    c.stream(true).expect("stream on");
    let t = c
        .next_telemetry(Duration::from_millis(200))
        .unwrap()
        .expect("the sample of this version");
    assert_eq!(
        t.t_s, 2.0,
        "the sample of protocol version {other} was read"
    );
}

#[test]
fn device_strings_reach_the_terminal_with_control_characters_escaped() {
    let port = Scripted::new(|seq| {
        let h = Header {
            seq,
            ..PROTOCOL_HEADER
        };
        if seq == 1 {
            reply_frame(h, &Response::Identity(identity("evil\x1b[2J\x07fw")))
        } else {
            reply_frame(
                h,
                &Response::Error(ErrorReply::BadFrame("x\x1b]0;pwned\x07\r")),
            )
        }
    });
    let (mut c, info) = Client::connect(port, Duration::ZERO).expect("identity");
    assert!(
        !info.firmware.chars().any(char::is_control),
        "{:?}",
        info.firmware
    );
    assert_eq!(info.firmware, "evil\\u{1b}[2J\\u{7}fw");
    let e = c.faults().unwrap_err().to_string();
    assert!(!e.chars().any(char::is_control), "{e:?}");
    assert!(e.contains("x\\u{1b}]0;pwned"), "{e}");
}

/// A device's model report reaches the user whole: the factors, the diagnosis in the core's
/// words, and its text with control characters escaped.
#[test]
fn the_model_report_reaches_the_user_with_its_diagnosis() {
    use shimmy_link::wire::{ModelReport, ParamReport};
    let port = Scripted::new(|seq| {
        let h = Header {
            seq,
            ..PROTOCOL_HEADER
        };
        if seq == 1 {
            return reply_frame(h, &Response::Identity(identity("fw")));
        }
        let p = |field, what, factor: f32, out_of_band| ParamReport {
            field,
            what,
            factor,
            sigma_ln: 0.02,
            band_low: 0.7,
            band_high: 1.3,
            out_of_band,
        };
        let params = [
            p("c_a", "tyre\x1b[2J", 1.02, false),
            p("k_d", "steering linkage stiffness", 0.5, true),
        ]
        .into_iter()
        .collect();
        reply_frame(
            h,
            &Response::Model(ModelReport {
                enabled: true,
                updates: 90,
                gated: 1,
                failures: 0,
                params,
            }),
        )
    });
    let (mut c, _) = Client::connect(port, Duration::ZERO).expect("identity");
    let m = c.model().expect("model report");
    assert_eq!(
        (m.enabled, m.updates, m.gated, m.params.len()),
        (true, 90, 1, 2)
    );
    assert_eq!(m.params[0].what, "tyre\\u{1b}[2J");
    let out: Vec<String> = m
        .params
        .iter()
        .filter(|p| p.out_of_band)
        .map(|p| p.statement().to_string())
        .collect();
    assert_eq!(out.len(), 1);
    assert!(
        out[0].starts_with("steering linkage stiffness (k_d) 50 % below the vehicle file (x0.50"),
        "{}",
        out[0]
    );
}

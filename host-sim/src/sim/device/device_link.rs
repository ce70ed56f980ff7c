//! The host side of the link (`shimmy-link`): a [`Client`] that sends typed requests and turns
//! every answer into an owned value or a clear error, over a [`Port`]: a serial port, a TCP
//! socket (QEMU's `-serial tcp:...`) or the in-process simulator device
//! ([`crate::sim::device::sim_device::SimDevice`]).
//!
//! Start-up: a device announces itself with a ready frame once its port listens (bytes sent
//! before are lost); [`Client::connect`] waits for it, and falls back to asking for the identity
//! (a device that was already running when the host connected). Every request frame starts
//! with a delimiter, which ends whatever partial frame a cut link left in the device's reader.

use crate::model::registry::{
    for_each_image_model, image_model_of_schema, Registered, StudyTypeVisitor,
};
use crate::model::study::StudyModel;
use anyhow::{anyhow, bail, Context, Result};
use shimmy_core::estimator::model_update::Statement;
use shimmy_core::vehicle::{
    check_record_value, decode_record, encode_record, RecordError, RecordVehicle, Vehicle,
    RECORD_MAX_BYTES,
};
use shimmy_link::frame::{self, Fed, FrameReader, DELIMITER, MAX_FRAME};
use shimmy_link::host::decode_reply;
use shimmy_link::wire::{
    ConfigProblem, ErrorReply, FaultReport, Header, LogEntry, Request, Response, Telemetry,
    PROTOCOL_HEADER,
};
use shimmy_link::PROTOCOL_VERSION;
use std::io::{Read, Write};
use std::time::{Duration, Instant};

/// A byte pipe to a device.
pub trait Port {
    /// Sends all of `bytes`.
    fn send(&mut self, bytes: &[u8]) -> Result<()>;
    /// Receives what is there within `timeout` (0 bytes: nothing came).
    fn receive(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize>;
}

/// A TCP socket (QEMU's `-serial tcp:HOST:PORT,server=on`).
pub struct TcpPort(std::net::TcpStream);

impl TcpPort {
    /// Connects to `addr` (`host:port`), retrying for up to `within` (QEMU may still be
    /// starting).
    pub fn connect(addr: &str, within: Duration) -> Result<Self> {
        let start = Instant::now();
        loop {
            match std::net::TcpStream::connect(addr) {
                Ok(s) => {
                    s.set_nodelay(true).ok();
                    return Ok(TcpPort(s));
                }
                Err(e) if start.elapsed() >= within => {
                    return Err(e).with_context(|| format!("connecting to {addr}"));
                }
                Err(_) => std::thread::sleep(Duration::from_millis(50)),
            }
        }
    }
}

fn timed_out(e: &std::io::Error) -> bool {
    matches!(
        e.kind(),
        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
    )
}

impl Port for TcpPort {
    fn send(&mut self, bytes: &[u8]) -> Result<()> {
        self.0.write_all(bytes).context("sending to the device")
    }
    fn receive(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize> {
        self.0
            .set_read_timeout(Some(timeout.max(Duration::from_millis(1))))?;
        match self.0.read(buf) {
            Ok(0) => bail!("the device closed the connection"),
            Ok(n) => Ok(n),
            Err(e) if timed_out(&e) => Ok(0),
            Err(e) => Err(e).context("receiving from the device"),
        }
    }
}

/// A serial port (the board's USART1 through a USB-serial adapter), 8N1.
pub struct SerialPort(Box<dyn serialport::SerialPort>);

impl SerialPort {
    /// Opens `path` at `baud`.
    pub fn open(path: &str, baud: u32) -> Result<Self> {
        let p = serialport::new(path, baud)
            .timeout(Duration::from_millis(10))
            .open()
            .with_context(|| format!("opening serial port {path}"))?;
        Ok(SerialPort(p))
    }
}

impl Port for SerialPort {
    fn send(&mut self, bytes: &[u8]) -> Result<()> {
        self.0.write_all(bytes).context("sending to the device")
    }
    fn receive(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize> {
        self.0
            .set_timeout(timeout.max(Duration::from_millis(1)))
            .context("serial port timeout")?;
        match self.0.read(buf) {
            Ok(n) => Ok(n),
            Err(e) if timed_out(&e) => Ok(0),
            Err(e) => Err(e).context("receiving from the device"),
        }
    }
}

/// The device's identity, owned.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DeviceInfo {
    /// Firmware name and version.
    pub firmware: String,
    /// `shimmy-core` version of the firmware.
    pub core: String,
    /// The device's protocol version.
    pub protocol: u16,
    /// The vehicle record schema it reads.
    pub vehicle_schema: u32,
    /// Capacity of its event log.
    pub log_capacity: u16,
}

/// The device's online model update, owned (its text through [`printable`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ModelState {
    /// The update runs.
    pub enabled: bool,
    /// Measurement updates applied.
    pub updates: u32,
    /// Measurements dropped by the innovation gate.
    pub gated: u32,
    /// Model solves that failed.
    pub failures: u32,
    /// The parameters, in the model's order.
    pub params: Vec<ParamState>,
}

/// One updated parameter as a device reports it.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamState {
    /// The vehicle file's field name.
    pub field: String,
    /// What it is, in words.
    pub what: String,
    /// The factor on the file's value.
    pub factor: f64,
    /// One-sigma uncertainty of ln(factor).
    pub sigma_ln: f64,
    /// The plausible band of the factor.
    pub band: (f64, f64),
    /// Outside its band by more than two sigmas.
    pub out_of_band: bool,
}

impl ParamState {
    /// The parameter as a line of the diagnosis (the core's words, its two-sigma interval).
    pub fn statement(&self) -> Statement<'_> {
        Statement {
            what: &self.what,
            field: &self.field,
            factor: self.factor,
            sigma_ln: self.sigma_ln,
            band: self.band,
        }
    }
}

/// The event log as read.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EventLog {
    /// Entries, oldest first.
    pub entries: Vec<LogEntry>,
    /// Entries the device dropped because its log was full.
    pub dropped: u32,
}

/// An owned reply (what is kept of a [`Response`] once its frame buffer is gone).
enum Reply {
    Info(DeviceInfo),
    Config(Vec<u8>, bool),
    Stored(bool),
    Events(Vec<LogEntry>, u16, u32),
    Cleared(u16),
    Faults(FaultReport),
    Streaming(bool),
    Telemetry(Telemetry),
    Ready(DeviceInfo),
    Model(ModelState),
}

fn owned(r: Response<'_>) -> std::result::Result<Reply, anyhow::Error> {
    let info = |i: shimmy_link::wire::Identity<'_>| DeviceInfo {
        firmware: printable(i.firmware),
        core: printable(i.core),
        protocol: i.protocol,
        vehicle_schema: i.vehicle_schema,
        log_capacity: i.log_capacity,
    };
    Ok(match r {
        Response::Ready(i) => Reply::Ready(info(i)),
        Response::Identity(i) => Reply::Info(info(i)),
        Response::Config { record, pending } => Reply::Config(record.to_vec(), pending),
        Response::ConfigStored { in_effect } => Reply::Stored(in_effect),
        Response::Events(p) => Reply::Events(p.entries.to_vec(), p.kept, p.dropped),
        Response::Cleared { removed } => Reply::Cleared(removed),
        Response::Faults(f) => Reply::Faults(f),
        Response::Streaming { on } => Reply::Streaming(on),
        Response::Telemetry(t) => Reply::Telemetry(t),
        Response::Model(m) => Reply::Model(ModelState {
            enabled: m.enabled,
            updates: m.updates,
            gated: m.gated,
            failures: m.failures,
            params: m
                .params
                .iter()
                .map(|p| ParamState {
                    field: printable(p.field),
                    what: printable(p.what),
                    factor: f64::from(p.factor),
                    sigma_ln: f64::from(p.sigma_ln),
                    band: (f64::from(p.band_low), f64::from(p.band_high)),
                    out_of_band: p.out_of_band,
                })
                .collect(),
        }),
        Response::Error(e) => return Err(device_error(&e)),
    })
}

/// Text from the device made safe for a terminal: control characters (an escape sequence that
/// would clear the screen or retitle the window, a bell, a carriage return that overwrites the
/// line) are shown escaped (`\u{1b}`), printable text as it is. Every string the device sends
/// passes through here before anything prints it.
pub fn printable(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_control() {
                c.escape_default().to_string()
            } else {
                c.to_string()
            }
        })
        .collect()
}

/// The device's refusal as a message for the user.
pub fn device_error(e: &ErrorReply<'_>) -> anyhow::Error {
    match e {
        ErrorReply::BadFrame(why) => anyhow!(
            "the device received a damaged frame ({})",
            printable(why)
        ),
        ErrorReply::TooLong => anyhow!(
            "the device received a frame longer than {MAX_FRAME} bytes and dropped it"
        ),
        ErrorReply::Version { device } => anyhow!(
            "protocol version mismatch: the device speaks version {device}, this tool {PROTOCOL_VERSION}"
        ),
        ErrorReply::UnknownRequest => anyhow!("the device does not know this request"),
        ErrorReply::NoSuchEntry { kept } => {
            anyhow!("no such log entry: the device's log holds {kept}")
        }
        ErrorReply::NotAtStandstill => anyhow!(
            "the device clears its log (a flash erase) only with the vehicle stopped and the damper idle for 2 s; nothing was removed"
        ),
        ErrorReply::Storage => {
            anyhow!("the device could not read its flash log; nothing was changed")
        }
        ErrorReply::Config(p) => anyhow!(
            "the device refused the configuration, nothing was stored: {}",
            config_problem(p)
        ),
    }
}

/// A vehicle-record problem in the core's words (the field with its allowed range).
fn config_problem(p: &ConfigProblem<'_>) -> String {
    match *p {
        ConfigProblem::Length { need, have } => {
            format!("vehicle record is {have} bytes, the device expects {need}")
        }
        ConfigProblem::Schema { found, expected } => {
            schema_mismatch(found, expected, "the device's")
        }
        ConfigProblem::Field {
            section,
            name,
            value,
            rule,
        } => {
            let (section, name, rule) = (printable(section), printable(name), printable(rule));
            // The field with its range, from the table of the model whose record has it.
            let checked = check_image_record_value(&section, &name, value);
            match checked {
                Some(Err(e)) if rule.is_empty() => e.to_string(),
                Some(_) if rule.is_empty() => {
                    format!("field `{section}.{name}` = {value}: refused")
                }
                _ => format!("field `{section}.{name}` = {value}: {rule}"),
            }
        }
    }
}

/// The field `section.name` = `value` checked against the field table of the first model's
/// firmware image whose record has that field (`None`: no image's record has it).
fn check_image_record_value(section: &str, name: &str, value: f64) -> Option<Result<(), String>> {
    struct Check<'a>(&'a str, &'a str, f64, Option<Result<(), String>>);
    impl StudyTypeVisitor for Check<'_> {
        fn visit<M: Registered<N> + StudyModel<N>, const N: usize>(&mut self) {
            if self.3.is_none() {
                self.3 = check_record_value::<M::Board>(self.0, self.1, self.2)
                    .map(|r| r.map_err(|e| e.to_string()));
            }
        }
    }
    let mut c = Check(section, name, value, None);
    for_each_image_model(&mut c);
    c.3
}

/// A record from the device read as a vehicle of the model `V`, or an error that names the
/// record's model when it is another.
pub fn read_record<V: RecordVehicle>(rec: &[u8]) -> Result<V> {
    decode_record::<V>(rec).map_err(|e| match e {
        RecordError::Schema { found, expected } => anyhow!(
            "the device's vehicle record is not readable: {}",
            schema_mismatch(found, expected, "this")
        ),
        e => anyhow!("the device's vehicle record is not readable: {e}"),
    })
}

/// A record of schema `found` where `whose` (the device's, this) decoder reads `expected`: the
/// models by name when the ids are the family's, else the ids.
pub fn schema_mismatch(found: u32, expected: u32, whose: &str) -> String {
    match (image_model_of_schema(found), image_model_of_schema(expected)) {
        (Some(f), Some(e)) => format!(
            "the vehicle record is a {f} vehicle (schema {found:#010x}), {whose} side stores {e} \
             vehicles (schema {expected:#010x}): another vehicle model"
        ),
        _ => format!(
            "vehicle record schema {found:#010x} is not {whose} {expected:#010x} (another field table)"
        ),
    }
}

/// How long the client waits for a reply.
pub const REPLY_TIMEOUT: Duration = Duration::from_millis(1500);

/// Typed requests to one device.
pub struct Client<P: Port> {
    port: P,
    seq: u16,
    reader: FrameReader,
    /// Bytes received and not yet fed to the reader.
    received: std::collections::VecDeque<u8>,
    timeout: Duration,
}

impl<P: Port> Client<P> {
    /// Opens the session: waits up to `ready_within` for the device's ready frame, else asks
    /// for its identity. Fails when the device speaks another protocol version.
    pub fn connect(port: P, ready_within: Duration) -> Result<(Self, DeviceInfo)> {
        let mut c = Client {
            port,
            seq: 0,
            reader: FrameReader::new(),
            received: std::collections::VecDeque::new(),
            timeout: REPLY_TIMEOUT,
        };
        let info = match c.wait_ready(ready_within)? {
            Some(info) => info,
            None => c.info()?,
        };
        if info.protocol != PROTOCOL_VERSION {
            bail!(
                "protocol version mismatch: the device speaks version {}, this tool {PROTOCOL_VERSION}",
                info.protocol
            );
        }
        Ok((c, info))
    }

    /// The port (tests reach the simulated device through it).
    pub fn port_mut(&mut self) -> &mut P {
        &mut self.port
    }

    fn wait_ready(&mut self, within: Duration) -> Result<Option<DeviceInfo>> {
        let deadline = Instant::now() + within;
        while let Some((_, r)) = self.next_frame(deadline)? {
            if let Ok(Reply::Ready(info)) = r {
                return Ok(Some(info));
            }
        }
        Ok(None)
    }

    /// The next decoded frame before `deadline` (None: nothing complete came).
    fn next_frame(&mut self, deadline: Instant) -> Result<Option<(Header, Result<Reply>)>> {
        loop {
            while let Some(b) = self.received.pop_front() {
                let decoded = match self.reader.feed(b) {
                    Fed::Pending => continue,
                    Fed::TooLong => (
                        PROTOCOL_HEADER,
                        Err(anyhow!(
                            "the device sent a frame longer than {MAX_FRAME} bytes"
                        )),
                    ),
                    Fed::Frame(f) => match decode_reply(f) {
                        (h, Ok(r)) => (h, owned(r)),
                        (h, Err(e)) => (h, Err(anyhow!("{e}"))),
                    },
                };
                return Ok(Some(decoded));
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(None);
            }
            let mut buf = [0u8; 512];
            let n = self.port.receive(&mut buf, deadline - now)?;
            self.received.extend(&buf[..n]);
        }
    }

    /// Sends `req` and waits for its reply (matched by `seq`); a damage report of the device
    /// (seq 0) is the error if no reply comes.
    fn call(&mut self, req: &Request<'_>) -> Result<Reply> {
        self.seq = self.seq.wrapping_add(1).max(1);
        let h = Header {
            seq: self.seq,
            ..PROTOCOL_HEADER
        };
        let mut out = vec![0u8; MAX_FRAME + 2];
        // A leading delimiter ends any partial frame a cut link left on the device.
        out[0] = DELIMITER;
        let n = frame::encode(h, req, &mut out[1..])
            .map_err(|e| anyhow!("request not sent: {}", e.text()))?;
        self.port.send(&out[..n + 1])?;
        let deadline = Instant::now() + self.timeout;
        let mut device_said = None;
        while let Some((rh, r)) = self.next_frame(deadline)? {
            if rh.seq == self.seq {
                return r;
            }
            if rh.seq == 0 {
                if let Err(e) = r {
                    device_said = Some(e);
                }
            }
        }
        Err(device_said.unwrap_or_else(|| {
            anyhow!(
                "no reply from the device within {:.1} s (link unplugged, wrong port or device not running?)",
                self.timeout.as_secs_f64()
            )
        }))
    }

    /// How long to wait for each reply.
    pub fn set_timeout(&mut self, t: Duration) {
        self.timeout = t;
    }

    /// Sends `bytes` as they are, ended by a delimiter (a diagnostic: what does the device make
    /// of a frame this tool would never send?); returns the device's verdict on it: its error
    /// reply as an error, or `Ok` if it answered normally.
    pub fn send_raw(&mut self, bytes: &[u8]) -> Result<()> {
        let mut out = Vec::with_capacity(bytes.len() + 2);
        out.push(DELIMITER);
        out.extend_from_slice(bytes);
        out.push(DELIMITER);
        self.port.send(&out)?;
        let deadline = Instant::now() + self.timeout;
        match self.next_frame(deadline)? {
            Some((_, r)) => r.map(|_| ()),
            None => bail!(
                "no reply from the device within {:.1} s",
                self.timeout.as_secs_f64()
            ),
        }
    }

    /// The device's identity.
    pub fn info(&mut self) -> Result<DeviceInfo> {
        match self.call(&Request::Identify)? {
            Reply::Info(i) => Ok(i),
            _ => bail!("the device answered the identity request with something else"),
        }
    }

    /// The stored car vehicle (validated by the core on this side too) and whether it still
    /// waits for standstill.
    pub fn config(&mut self) -> Result<(Vehicle, bool)> {
        let (rec, pending) = self.config_record()?;
        Ok((read_record(&rec)?, pending))
    }

    /// The stored vehicle's record as the device sent it (its schema id names its model,
    /// [`image_model_of_schema`]) and whether it still waits for standstill.
    pub fn config_record(&mut self) -> Result<(Vec<u8>, bool)> {
        match self.call(&Request::GetConfig)? {
            Reply::Config(rec, pending) => Ok((rec, pending)),
            _ => bail!("the device answered the configuration request with something else"),
        }
    }

    /// Stores `v`, a vehicle of its model, on the device (validated by the core here first);
    /// returns whether it is in effect already (standstill) or waits for the next standstill.
    /// A device that stores another model refuses it (its schema id).
    pub fn set_config<V: RecordVehicle>(&mut self, v: &V) -> Result<bool> {
        v.check_all()?;
        let mut rec = [0u8; RECORD_MAX_BYTES];
        let n = encode_record(v, &mut rec)?;
        self.set_record(&rec[..n])
    }

    /// Sends a raw vehicle record (tests: what the device does with a bad one).
    pub fn set_record(&mut self, record: &[u8]) -> Result<bool> {
        match self.call(&Request::SetConfig(record))? {
            Reply::Stored(in_effect) => Ok(in_effect),
            _ => bail!("the device answered the configuration write with something else"),
        }
    }

    /// The whole event log, page by page.
    pub fn events(&mut self) -> Result<EventLog> {
        let mut log = EventLog::default();
        loop {
            let first = u16::try_from(log.entries.len()).context("log index")?;
            match self.call(&Request::ReadEvents { first })? {
                Reply::Events(page, kept, dropped) => {
                    log.dropped = dropped;
                    let got = page.len();
                    log.entries.extend(page);
                    if got == 0 || log.entries.len() >= usize::from(kept) {
                        return Ok(log);
                    }
                }
                _ => bail!("the device answered the log request with something else"),
            }
        }
    }

    /// Empties the device's log; returns the entries removed.
    pub fn clear_events(&mut self) -> Result<u16> {
        match self.call(&Request::ClearEvents)? {
            Reply::Cleared(n) => Ok(n),
            _ => bail!("the device answered the clear request with something else"),
        }
    }

    /// The fault record.
    pub fn faults(&mut self) -> Result<FaultReport> {
        match self.call(&Request::ReadFaults)? {
            Reply::Faults(f) => Ok(f),
            _ => bail!("the device answered the fault request with something else"),
        }
    }

    /// The online model update: parameters, uncertainty, diagnosis.
    pub fn model(&mut self) -> Result<ModelState> {
        match self.call(&Request::ReadModel)? {
            Reply::Model(m) => Ok(m),
            _ => bail!("the device answered the model request with something else"),
        }
    }

    /// Starts or stops the telemetry stream.
    pub fn stream(&mut self, on: bool) -> Result<()> {
        match self.call(&Request::Telemetry { on })? {
            Reply::Streaming(x) if x == on => Ok(()),
            _ => bail!("the device did not switch its stream"),
        }
    }

    /// The next telemetry sample of the stream within `within` (None: none came).
    pub fn next_telemetry(&mut self, within: Duration) -> Result<Option<Telemetry>> {
        let deadline = Instant::now() + within;
        while let Some((_, r)) = self.next_frame(deadline)? {
            if let Ok(Reply::Telemetry(t)) = r {
                return Ok(Some(t));
            }
        }
        Ok(None)
    }
}

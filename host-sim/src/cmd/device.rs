//! `shimmy-sim device ...`: the host tool of the link. Reads a device's identity, gets and sets
//! its vehicle configuration (vehicle TOML files), reads its event log (table and CSV) and fault
//! record, and watches its live margin report; over a serial port (`--serial`), a TCP socket
//! (`--tcp`, QEMU) or the in-process simulator device (`--sim`, no board needed).

use crate::model::registry::{
    self, for_each_image_model, image_model_of_schema, image_models, Registered, StudyTypeVisitor,
    StudyVisitor,
};
use crate::model::study::StudyModel;
use crate::sim::device::device_link::{
    read_record, schema_mismatch, Client, DeviceInfo, EventLog, ModelState, ParamState, Port,
    SerialPort, TcpPort,
};
use crate::sim::device::sim_device::SimDevice;
use crate::sim::input::vehicle_file;
use anyhow::{bail, Result};
use clap::{Args, Subcommand};
use shimmy_core::estimator::model_update::Statement;
use shimmy_core::supervisor::faults::{FaultKind, FaultSet};
use shimmy_core::vehicle::{
    encode_record, record_schema_of, RecordVehicle, Vehicle, RECORD_HEADER_BYTES, RECORD_MAX_BYTES,
};
use shimmy_link::wire::{
    cause_name, fault_name, level_name, DiagnosisEvent, FaultReport, LogEntry,
};
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// Where the device is and what to do with it.
#[derive(Args, Debug)]
pub struct DeviceArgs {
    /// Serial port of a board (its USART1 through a USB-serial adapter), e.g. /dev/ttyUSB0.
    #[arg(long, conflicts_with_all = ["tcp", "sim"])]
    pub serial: Option<String>,
    /// Serial speed, baud (the firmware's).
    #[arg(long, default_value_t = shimmy_link::LINK_BAUD)]
    pub baud: u32,
    /// TCP address of a device, e.g. QEMU's `-serial tcp:127.0.0.1:4321,server=on`.
    #[arg(long, conflicts_with = "sim")]
    pub tcp: Option<String>,
    /// The in-process simulated device (a simulated drive with a shimmy warning and a fault).
    #[arg(long)]
    pub sim: bool,
    /// The simulated device's vehicle (with `--sim`): a set name or a vehicle file, of the car
    /// or the mining truck (the device then stores that model's vehicle records).
    #[arg(long, default_value = "nominal", requires = "sim")]
    pub vehicle: String,
    /// How long to wait for the device's ready frame before asking for its identity, s.
    #[arg(long, default_value_t = 2.0)]
    pub ready_s: f64,
    /// What to do.
    #[command(subcommand)]
    pub action: DeviceAction,
}

/// A device command.
#[derive(Subcommand, Debug)]
pub enum DeviceAction {
    /// Firmware, core and protocol versions, vehicle schema, log capacity.
    Info,
    /// The vehicle configuration.
    Config {
        /// Get or set.
        #[command(subcommand)]
        action: ConfigAction,
    },
    /// The event log: shimmy episodes and faults, as a table (and CSV).
    Events {
        /// Also write the log as CSV to this file (`-`: standard output instead of the table).
        #[arg(long)]
        csv: Option<PathBuf>,
        /// Empty the log after reading it.
        #[arg(long)]
        clear: bool,
    },
    /// The fault record: resets, reset cause, latched and active faults.
    Faults,
    /// The online model update: each parameter's factor on the vehicle file with its 2-sigma
    /// interval and plausible band, and the diagnosis of a part outside its band.
    Model,
    /// The live margin report (the device's telemetry stream) in the terminal.
    Watch {
        /// Stop after this many seconds.
        #[arg(long, default_value_t = 10.0)]
        seconds: f64,
    },
}

/// Get or set the configuration.
#[derive(Subcommand, Debug)]
pub enum ConfigAction {
    /// Read the stored vehicle and write it as a vehicle TOML file.
    Get {
        /// File to write (default: standard output).
        // A file, not a folder: not the shared `--out` (`cmd::OutArg`).
        #[arg(long, short)]
        out: Option<PathBuf>,
    },
    /// Validate a vehicle file here, then store it on the device (validated there again; it
    /// takes effect at standstill).
    Set {
        /// The vehicle file (or a set name).
        file: String,
    },
}

/// Runs a device command.
pub fn command(a: &DeviceArgs) -> Result<()> {
    if !(a.ready_s.is_finite() && (0.0..=60.0).contains(&a.ready_s)) {
        bail!("--ready-s {}: allowed 0 ..= 60 s", a.ready_s);
    }
    let ready = Duration::from_secs_f64(a.ready_s);
    match (&a.serial, &a.tcp, a.sim) {
        (Some(path), None, false) => run(SerialPort::open(path, a.baud)?, ready, &a.action),
        (None, Some(addr), false) => run(
            TcpPort::connect(addr, Duration::from_secs(5))?,
            ready,
            &a.action,
        ),
        (None, None, true) => {
            let v = vehicle_file::load_model(&a.vehicle)?;
            eprintln!("simulating the drive of the in-process device ...");
            struct Sim<'a>(Duration, &'a DeviceAction);
            impl StudyVisitor for Sim<'_> {
                type Output = Result<()>;
                fn visit<M: Registered<N> + StudyModel<N>, const N: usize>(
                    self,
                    v: M::File,
                ) -> Result<()> {
                    run(
                        SimDevice::new(&registry::family::<M, N>(v)?)?,
                        self.0,
                        self.1,
                    )
                }
            }
            match registry::with_image_model(v, Sim(ready, &a.action)) {
                Ok(r) => r,
                Err(other) => bail!(
                    "--vehicle {}: a {} model; the in-process device stores a vehicle of the {} \
                     models",
                    a.vehicle,
                    other.model_name(),
                    image_models()
                ),
            }
        }
        _ => bail!("say where the device is: --serial PORT, --tcp HOST:PORT or --sim"),
    }
}

fn run<P: Port>(port: P, ready: Duration, action: &DeviceAction) -> Result<()> {
    let (mut c, info) = Client::connect(port, ready)?;
    match action {
        DeviceAction::Info => print!("{}", info_text(&info)),
        DeviceAction::Config {
            action: ConfigAction::Get { out },
        } => {
            let (rec, pending) = c.config_record()?;
            let text = record_toml(&rec)?;
            match out {
                Some(p) => {
                    crate::sim::input::files::write_file(p, &text)?;
                    eprintln!(
                        "vehicle written to {}{}",
                        p.display(),
                        if pending {
                            " (stored, takes effect at the next standstill)"
                        } else {
                            ""
                        }
                    );
                }
                None => print!("{text}"),
            }
        }
        DeviceAction::Config {
            action: ConfigAction::Set { file },
        } => {
            struct Store<'a, P: Port>(&'a mut Client<P>, &'a DeviceInfo);
            impl<P: Port> StudyVisitor for Store<'_, P> {
                type Output = Result<(bool, usize)>;
                fn visit<M: Registered<N> + StudyModel<N>, const N: usize>(
                    self,
                    v: M::File,
                ) -> Result<(bool, usize)> {
                    let board = M::board_vehicle(&registry::family::<M, N>(v)?);
                    store_and_read_back(self.0, self.1, &board)
                }
            }
            let (now, fields) = match registry::with_image_model(
                vehicle_file::load_model(file)?,
                Store(&mut c, &info),
            ) {
                Ok(r) => r?,
                Err(other) => bail!(
                    "vehicle `{file}` is a {} model; a device stores a vehicle of the {} models",
                    other.model_name(),
                    image_models()
                ),
            };
            println!(
                "configuration stored and read back identical ({fields} fields); {}",
                if now {
                    "in effect (vehicle at standstill)"
                } else {
                    "takes effect at the next standstill (2 s stopped with the damper idle: a \
                     board saves it to flash then and restarts into it)"
                }
            );
        }
        DeviceAction::Events { csv, clear } => {
            let log = c.events()?;
            // the update's parameters name a logged diagnosis
            let params = c.model()?.params;
            match csv.as_deref() {
                Some(p) if p.as_os_str() == "-" => print!("{}", events_csv(&log, &params)),
                Some(p) => {
                    crate::sim::input::files::write_file(p, events_csv(&log, &params))?;
                    print!("{}", events_table(&log, &params));
                    eprintln!("CSV written to {}", p.display());
                }
                None => print!("{}", events_table(&log, &params)),
            }
            if *clear {
                let n = c.clear_events()?;
                eprintln!("log cleared ({n} entries removed)");
            }
        }
        DeviceAction::Faults => print!("{}", faults_text(&c.faults()?)),
        DeviceAction::Model => print!("{}", model_text(&c.model()?)),
        DeviceAction::Watch { seconds } => {
            if !(seconds.is_finite() && (0.0..=86_400.0).contains(seconds)) {
                bail!("--seconds {seconds}: allowed 0 ..= 86400");
            }
            watch(&mut c, Duration::from_secs_f64(*seconds))?;
        }
    }
    Ok(())
}

/// The device's record as a vehicle file of its model (of a model with a firmware image).
fn record_toml(rec: &[u8]) -> Result<String> {
    struct Read<'a>(&'a [u8], u32, Option<Result<String>>);
    impl StudyTypeVisitor for Read<'_> {
        fn visit<M: Registered<N> + StudyModel<N>, const N: usize>(&mut self) {
            if self.2.is_none() && record_schema_of::<M::Board>() == self.1 {
                self.2 =
                    Some(read_record::<M::Board>(self.0).map(|b| {
                        vehicle_file::model_to_toml::<M, N>(&M::file_of(&M::from_board(&b)))
                    }));
            }
        }
    }
    let schema = rec
        .get(..4)
        .and_then(|b| <[u8; 4]>::try_from(b).ok())
        .map(u32::from_le_bytes);
    let mut read = Read(rec, schema.unwrap_or(0), None);
    for_each_image_model(&mut read);
    // a record of no image's schema: the car's reader names what is wrong with it
    read.2
        .unwrap_or_else(|| Ok(vehicle_file::to_toml(&read_record::<Vehicle>(rec)?)))
}

/// Stores `v` on the device and reads it back: it must hold exactly the record sent. Refused
/// here, before anything is sent, when the device stores another model's vehicles. Returns
/// whether it is in effect and the number of fields.
fn store_and_read_back<P: Port, V: RecordVehicle>(
    c: &mut Client<P>,
    info: &DeviceInfo,
    v: &V,
) -> Result<(bool, usize)> {
    let schema = record_schema_of::<V>();
    if info.vehicle_schema != schema {
        bail!(
            "nothing sent: {}",
            schema_mismatch(schema, info.vehicle_schema, "the device's")
        );
    }
    let now = c.set_config(v)?;
    let mut sent = [0u8; RECORD_MAX_BYTES];
    let n = encode_record(v, &mut sent)?;
    let (back, _) = c.config_record()?;
    let values = |r: &[u8]| -> Vec<[u8; 8]> {
        r.get(RECORD_HEADER_BYTES..)
            .unwrap_or_default()
            .as_chunks::<8>()
            .0
            .to_vec()
    };
    let (a, b) = (values(&sent[..n]), values(&back));
    let differ: Vec<String> = (0..V::values().max(b.len()))
        .filter(|&i| a.get(i) != b.get(i))
        .map(|i| match V::describe(i) {
            Some((section, name, _)) => format!("{section}.{name}"),
            None => format!("value {i}"),
        })
        .collect();
    if !differ.is_empty() || back.get(..RECORD_HEADER_BYTES) != sent.get(..RECORD_HEADER_BYTES) {
        bail!(
            "the device reads back another configuration (fields {})",
            differ.join(", ")
        );
    }
    Ok((now, V::values()))
}

fn info_text(i: &DeviceInfo) -> String {
    format!(
        "firmware        {}\ncore            {}\nprotocol        {}\nvehicle schema  {:#010x}{}\nlog capacity    {} entries\n",
        i.firmware,
        i.core,
        i.protocol,
        i.vehicle_schema,
        match image_model_of_schema(i.vehicle_schema) {
            Some(m) => format!(" ({m} vehicles, a record this tool reads)"),
            None => " (NOT one this tool reads: configurations cannot be exchanged)".into(),
        },
        i.log_capacity
    )
}

fn names(bits: u32) -> String {
    let v: Vec<&str> = FaultSet::from_bits(bits)
        .iter()
        .map(FaultKind::name)
        .collect();
    if v.is_empty() {
        "none".into()
    } else {
        v.join(", ")
    }
}

fn model_text(m: &ModelState) -> String {
    if !m.enabled {
        return "online model update: off\n".into();
    }
    let mut s = format!(
        "online model update: {} measurements applied, {} gated, {} failed solves\n",
        m.updates, m.gated, m.failures
    );
    if m.params.is_empty() {
        s += "the vehicle's model has no updated parameters\n";
        return s;
    }
    s += "parameter                     field      factor  2 sigma          plausible\n";
    for p in &m.params {
        let (lo, hi) = p.statement().two_sigma();
        let _ = writeln!(
            s,
            "{:<29} {:<10} x{:<6.3} x{:.3}-x{:.3}  x{:.2}-x{:.2}{}",
            p.what,
            p.field,
            p.factor,
            lo,
            hi,
            p.band.0,
            p.band.1,
            if p.out_of_band { "  OUT OF BAND" } else { "" }
        );
    }
    let out: Vec<String> = m
        .params
        .iter()
        .filter(|p| p.out_of_band)
        .map(|p| p.statement().to_string())
        .collect();
    if out.is_empty() {
        s += "diagnosis: every part within its plausible band\n";
    }
    for line in out {
        let _ = writeln!(s, "diagnosis: {line}");
    }
    s
}

fn faults_text(f: &FaultReport) -> String {
    let cause = cause_name(f.last_cause);
    format!(
        "resets since power-on   {}\nlast reset cause        {cause}\nabnormal resets in row  {}\nuptime                  {:.3} s\nlatched faults          {}\nactive faults           {}\nfaults raised           {}\n",
        f.resets,
        f.quick_resets,
        f64::from(f.uptime_ms) * 1e-3,
        names(f.latched),
        names(f.active),
        f.raised
    )
}

/// The CSV header of the event log.
pub const EVENTS_CSV_HEADER: &str = "index,kind,start_s,speed_kmh,freq_hz,peak_amplitude_mrad,duration_s,shimmy_s,level,open,peak_current_a,mean_current_a,fault,latched,cause,resets_since_power_on,boot_count,diagnosis";

/// A logged diagnosis in words, its parameter named by `params` (the device's update
/// parameters, in their order).
pub fn diagnosis_text(d: &DiagnosisEvent, params: &[ParamState]) -> String {
    let Some(i) = d.param else {
        return "model update: every part within its band".into();
    };
    match params.get(usize::from(i)) {
        Some(p) => Statement {
            what: &p.what,
            field: &p.field,
            factor: f64::from(d.factor),
            sigma_ln: f64::from(d.sigma_ln),
            band: (f64::from(d.band_low), f64::from(d.band_high)),
        }
        .to_string(),
        None => format!(
            "update parameter {i} (not one this device reports) x{:.2}",
            d.factor
        ),
    }
}

/// The log as CSV, one row per entry (shimmy columns empty for a fault and vice versa), a
/// diagnosis named by `params`.
pub fn events_csv(log: &EventLog, params: &[ParamState]) -> String {
    let mut s = String::from(EVENTS_CSV_HEADER);
    s.push('\n');
    for (i, e) in log.entries.iter().enumerate() {
        let _ = match e {
            LogEntry::Shimmy(x) => writeln!(
                s,
                "{i},shimmy,{:.3},{:.1},{:.2},{:.2},{:.2},{:.2},{},{},{:.3},{:.3},,,,,,",
                x.start_s,
                f64::from(x.speed_mps) * 3.6,
                x.freq_hz,
                x.peak_amplitude_rad * 1e3,
                x.duration_s,
                x.shimmy_s,
                level_name(x.level),
                x.open,
                x.peak_current_a,
                x.mean_current_a
            ),
            LogEntry::Fault(f) => writeln!(
                s,
                "{i},fault,{:.3},,,,,,,,,,{},{},,,,",
                f64::from(f.t_ms) * 1e-3,
                fault_name(f.kind),
                f.latched
            ),
            // A boot has no time of its own (each run's clock starts at 0).
            LogEntry::Boot(b) => writeln!(
                s,
                "{i},boot,,,,,,,,,,,,,{},{},{},",
                cause_name(b.cause),
                b.resets_since_power_on,
                b.boot_count
            ),
            // the statement has commas: quoted
            LogEntry::Diagnosis(d) => writeln!(
                s,
                "{i},diagnosis,{:.3},,,,,,,,,,,,,,,\"{}\"",
                f64::from(d.t_ms) * 1e-3,
                diagnosis_text(d, params).replace('"', "'")
            ),
        };
    }
    s
}

fn events_table(log: &EventLog, params: &[ParamState]) -> String {
    let mut s = format!(
        "{} entries{}\n  #  kind     start s   km/h    Hz  peak mrad  dur s  level                 I peak/mean A  fault\n",
        log.entries.len(),
        if log.dropped > 0 {
            format!(" ({} older ones dropped: log full)", log.dropped)
        } else {
            String::new()
        }
    );
    for (i, e) in log.entries.iter().enumerate() {
        let _ = match e {
            LogEntry::Shimmy(x) => writeln!(
                s,
                "{i:>3}  shimmy {:>9.3} {:>6.1} {:>5.2} {:>10.2} {:>6.2}  {:<20}  {:.2}/{:.2}{}",
                x.start_s,
                f64::from(x.speed_mps) * 3.6,
                x.freq_hz,
                x.peak_amplitude_rad * 1e3,
                x.duration_s,
                level_name(x.level),
                x.peak_current_a,
                x.mean_current_a,
                if x.open { "  (still going on)" } else { "" }
            ),
            LogEntry::Fault(f) => writeln!(
                s,
                "{i:>3}  fault  {:>9.3} {:>59}  {}{}",
                f64::from(f.t_ms) * 1e-3,
                "",
                fault_name(f.kind),
                if f.latched { " (latched)" } else { "" }
            ),
            LogEntry::Boot(b) => writeln!(
                s,
                "{i:>3}  boot   {:>9} {:>59}  boot {} of this board, cause {}, {} resets since power-on",
                "",
                "",
                b.boot_count,
                cause_name(b.cause),
                b.resets_since_power_on
            ),
            LogEntry::Diagnosis(d) => writeln!(
                s,
                "{i:>3}  model  {:>9.3} {:>59}  {}",
                f64::from(d.t_ms) * 1e-3,
                "",
                diagnosis_text(d, params)
            ),
        };
    }
    s
}

fn watch<P: Port>(c: &mut Client<P>, for_: Duration) -> Result<()> {
    c.stream(true)?;
    println!(
        "     t s    km/h  zeta data  +- sigma  zeta fast     Hz  zeta model  margin km/h  level"
    );
    let end = Instant::now() + for_;
    let mut n = 0u32;
    while Instant::now() < end {
        let left = end.saturating_duration_since(Instant::now());
        let Some(t) = c.next_telemetry(left.min(Duration::from_millis(500)))? else {
            continue;
        };
        n += 1;
        println!(
            "{:>8.2} {:>7.1} {:>10.4} {:>9.4} {:>10.4} {:>6.2} {:>11.4} {:>12.1}  {}{}",
            t.t_s,
            f64::from(t.speed_mps) * 3.6,
            t.zeta_data,
            t.sigma_zeta_data,
            t.zeta_fast,
            t.freq_hz,
            t.zeta_model,
            f64::from(t.speed_margin_mps) * 3.6,
            level_name(t.level),
            if t.valid { "" } else { " (not valid)" }
        );
    }
    c.stream(false)?;
    if n == 0 {
        bail!(
            "no margin report came from the device within {:.1} s",
            for_.as_secs_f64()
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::device::device_link::EventLog;

    /// A logged diagnosis reads as the model update's statement, its parameter named by the
    /// device's update parameters; its end, and an index the device does not report, read
    /// as such; in the CSV the statement is one quoted field of the last column.
    #[test]
    fn a_logged_diagnosis_is_named_by_the_devices_update_parameters() {
        let params = vec![ParamState {
            field: "k_d".into(),
            what: "steering linkage stiffness".into(),
            factor: 1.0,
            sigma_ln: 0.1,
            band: (0.7, 1.3),
            out_of_band: false,
        }];
        let d = DiagnosisEvent {
            t_ms: 61_500,
            param: Some(0),
            factor: 0.5,
            sigma_ln: 0.01,
            band_low: 0.7,
            band_high: 1.3,
        };
        let text = diagnosis_text(&d, &params);
        assert!(
            text.starts_with("steering linkage stiffness (k_d) 50 % below the vehicle file"),
            "{text}"
        );
        let ended = DiagnosisEvent { param: None, ..d };
        assert!(diagnosis_text(&ended, &params).contains("every part within its band"));
        let unknown = DiagnosisEvent {
            param: Some(3),
            ..d
        };
        assert!(diagnosis_text(&unknown, &params).contains("update parameter 3"));
        let log = EventLog {
            dropped: 0,
            entries: vec![LogEntry::Diagnosis(d)],
        };
        let csv = events_csv(&log, &params);
        let row = csv.lines().nth(1).unwrap();
        assert!(row.starts_with("0,diagnosis,61.500,"), "{row}");
        assert_eq!(
            row.split(",\"").nth(1).map(|s| s.trim_end_matches('"')),
            Some(text.as_str())
        );
        assert_eq!(
            csv.lines().next().unwrap().split(',').count(),
            row.split(",\"").next().unwrap().split(',').count() + 1
        );
        assert!(events_table(&log, &params).contains("model     61.500"));
    }
}

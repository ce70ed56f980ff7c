//! What goes into the event log, and a RAM-held log to put it in.
//!
//! [`Recorder`] turns what the device's tasks see (the core monitor after each margin update,
//! the damper commands in between, the supervisor's active and latched fault bits) into
//! [`LogEntry`]s: one [`ShimmyEvent`] per closed monitor episode, with the controller's action
//! during it, and one [`FaultEvent`] per fault that became active. The episode still open is
//! not an entry yet ([`Recorder::open_event`] shows it). [`DiagnosisWatch`] makes a
//! [`DiagnosisEvent`] each time the online model update's diagnosis names another part.
//!
//! [`RamLog`] is a bounded queue of entries in RAM (oldest dropped when full, drop count kept):
//! the simulator's device keeps its log there; the firmware's recorder feeds the flash log
//! (`shimmy_firmware::store`) behind the same [`EventSink`]. [`Pager`] cuts either into the
//! pages a host reads.

use shimmy_core::estimator::model_update::ParamEstimate;
use shimmy_core::estimator::monitor::{Event, Monitor};
use shimmy_core::supervisor::faults::FaultKind;

use crate::wire::{
    fault_code, level_code, DiagnosisEvent, FaultEvent, LogEntry, ShimmyEvent, EVENTS_PER_PAGE,
};

/// Where recorded entries go (a RAM queue, the flash log).
pub trait EventSink {
    /// Appends an entry (the oldest goes when full).
    fn append(&mut self, e: LogEntry);
}

/// Watches the online model update's diagnosis
/// (`shimmy_core::estimator::model_update::ModelUpdater::diagnosis_indexed`): an entry when it
/// names another part than the last entry did, or none any more; nothing while it stays.
#[derive(Clone, Copy, Debug, Default)]
pub struct DiagnosisWatch {
    /// The part the last entry named (`None`: none, or no entry yet).
    named: Option<u8>,
}

impl DiagnosisWatch {
    /// A watch that has logged nothing yet.
    pub const fn new() -> Self {
        Self { named: None }
    }

    /// The entry for the diagnosis `d` (the parameter's index and its estimate) at `t_ms`, if
    /// it names another part than before.
    pub fn on_update(
        &mut self,
        t_ms: u32,
        d: Option<(usize, ParamEstimate)>,
    ) -> Option<DiagnosisEvent> {
        let param = d.and_then(|(i, _)| u8::try_from(i).ok());
        if param == self.named {
            return None;
        }
        self.named = param;
        let e = d.map(|(_, e)| e);
        let num = |f: fn(&ParamEstimate) -> f64| e.as_ref().map_or(0.0, |e| f(e) as f32);
        Some(DiagnosisEvent {
            t_ms,
            param,
            factor: num(|e| e.factor),
            sigma_ln: num(|e| e.sigma_ln),
            band_low: num(|e| e.band.0),
            band_high: num(|e| e.band.1),
        })
    }
}

/// Turns monitor episodes and fault bits into log entries.
#[derive(Clone, Debug, Default)]
pub struct Recorder {
    /// Closed episodes of the monitor already recorded (kept + dropped by the monitor).
    closed_seen: u32,
    /// Commands since the last margin update: highest, sum, count.
    since_update: (f32, f32, u32),
    /// Controller action during the open episode: highest, sum, count.
    episode: (f32, f32, u32),
    /// Fault bits active at the last look.
    active: u32,
    /// Fault bits latched at the last look.
    latched: u32,
}

fn merge(a: (f32, f32, u32), b: (f32, f32, u32)) -> (f32, f32, u32) {
    (a.0.max(b.0), a.1 + b.1, a.2.saturating_add(b.2))
}

impl Recorder {
    /// A recorder that has seen nothing.
    pub const fn new() -> Self {
        Recorder {
            closed_seen: 0,
            since_update: (0.0, 0.0, 0),
            episode: (0.0, 0.0, 0),
            active: 0,
            latched: 0,
        }
    }

    /// A recorder after a reset that restored the `latched` fault bits: the run that latched
    /// them logged them, so they are not logged again.
    pub const fn after_boot(latched: u32) -> Self {
        Recorder {
            active: latched,
            latched,
            ..Recorder::new()
        }
    }

    /// One control step's damper command, A (non-finite ones are skipped).
    pub fn on_command(&mut self, cmd_a: f32) {
        if cmd_a.is_finite() {
            self.since_update = merge(self.since_update, (cmd_a, cmd_a, 1));
        }
    }

    /// After a margin update: records the episodes the monitor closed since the last call.
    pub fn on_update<const N: usize>(&mut self, monitor: &Monitor<N>, sink: &mut impl EventSink) {
        let open = monitor.events().last().is_some_and(|e| e.open);
        let closed_kept = monitor.events().filter(|e| !e.open).count();
        let closed_total = monitor
            .dropped_events()
            .saturating_add(u32::try_from(closed_kept).unwrap_or(u32::MAX));
        let new = closed_total.saturating_sub(self.closed_seen);
        let commands = core::mem::take(&mut self.since_update);
        if new > 0 {
            // The commands of this update belong to the episode that just closed.
            let action = merge(self.episode, commands);
            let skip = closed_kept.saturating_sub(usize::try_from(new).unwrap_or(usize::MAX));
            for (i, e) in monitor.events().filter(|e| !e.open).skip(skip).enumerate() {
                // Only the last closed episode can have been open at the last update.
                let last = i + 1 == usize::try_from(new).unwrap_or(0).min(closed_kept);
                let act = if last { action } else { (0.0, 0.0, 0) };
                sink.append(LogEntry::Shimmy(shimmy_event(e, act)));
            }
            self.episode = (0.0, 0.0, 0);
        }
        if open {
            let prior = if new > 0 { (0.0, 0.0, 0) } else { self.episode };
            self.episode = merge(prior, commands);
        }
        self.closed_seen = closed_total;
    }

    /// The episode going on now, if any, with the controller's action so far.
    pub fn open_event<const N: usize>(&self, monitor: &Monitor<N>) -> Option<ShimmyEvent> {
        let e = monitor.events().last().filter(|e| e.open)?;
        Some(shimmy_event(e, merge(self.episode, self.since_update)))
    }

    /// The supervisor's fault bits at `t_ms`: every bit newly active, or newly latched (an
    /// intermittent fault escalated), becomes a [`FaultEvent`].
    pub fn on_faults(&mut self, t_ms: u32, active: u32, latched: u32, sink: &mut impl EventSink) {
        let raised = (active & !self.active) | (latched & !self.latched);
        self.active = active;
        self.latched = latched;
        if raised == 0 {
            // the usual update: no fault raised, no kind to look at
            return;
        }
        for (i, kind) in FaultKind::ALL.iter().enumerate() {
            let bit = 1u32
                .checked_shl(u32::try_from(i).unwrap_or(32))
                .unwrap_or(0);
            if raised & bit != 0 {
                sink.append(LogEntry::Fault(FaultEvent {
                    t_ms,
                    kind: fault_code(*kind),
                    latched: latched & bit != 0,
                }));
            }
        }
    }
}

fn shimmy_event(e: &Event, (peak, sum, n): (f32, f32, u32)) -> ShimmyEvent {
    ShimmyEvent {
        start_s: e.start_s,
        speed_mps: e.speed_mps,
        freq_hz: e.freq_hz,
        peak_amplitude_rad: e.peak_amplitude_rad,
        duration_s: e.duration_s,
        shimmy_s: e.shimmy_s,
        level: level_code(e.worst),
        open: e.open,
        peak_current_a: if n > 0 { peak } else { f32::NAN },
        mean_current_a: if n > 0 { sum / n as f32 } else { f32::NAN },
    }
}

/// Collects one page of a log read front to back: offered entry `first` and the ones after it,
/// up to [`EVENTS_PER_PAGE`]; counts every entry offered.
pub struct Pager<'a> {
    first: u16,
    seen: u16,
    page: &'a mut heapless::Vec<LogEntry, EVENTS_PER_PAGE>,
}

impl<'a> Pager<'a> {
    /// A page from entry `first` into `page` (emptied).
    pub fn new(first: u16, page: &'a mut heapless::Vec<LogEntry, EVENTS_PER_PAGE>) -> Self {
        page.clear();
        Pager {
            first,
            seen: 0,
            page,
        }
    }

    /// The next entry of the log.
    pub fn offer(&mut self, e: &LogEntry) {
        if self.seen >= self.first {
            let _ = self.page.push(*e);
        }
        self.seen = self.seen.saturating_add(1);
    }

    /// Entries offered so far.
    pub fn seen(&self) -> u16 {
        self.seen
    }
}

/// A bounded log in RAM: `N` entries, the oldest dropped when full.
#[derive(Clone, Debug, Default)]
pub struct RamLog<const N: usize> {
    entries: heapless::Deque<LogEntry, N>,
    dropped: u32,
}

impl<const N: usize> RamLog<N> {
    /// An empty log.
    pub const fn new() -> Self {
        RamLog {
            entries: heapless::Deque::new(),
            dropped: 0,
        }
    }

    /// Entries kept and entries dropped since the last clear.
    pub fn len(&self) -> (u16, u32) {
        (
            u16::try_from(self.entries.len()).unwrap_or(u16::MAX),
            self.dropped,
        )
    }

    /// No entry kept.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Entry `i`, oldest first.
    pub fn get(&self, i: u16) -> Option<LogEntry> {
        self.entries.iter().nth(usize::from(i)).copied()
    }

    /// The log as a host reads it, through [`Pager`]: the kept entries, then the episode still
    /// `open` (if any) as one more; returns the entries and the dropped count.
    pub fn page(&self, open: Option<ShimmyEvent>, pager: &mut Pager<'_>) -> (u16, u32) {
        for e in &self.entries {
            pager.offer(e);
        }
        if let Some(e) = open {
            pager.offer(&LogEntry::Shimmy(e));
        }
        (pager.seen(), self.dropped)
    }

    /// Empties the log; returns how many entries it held.
    pub fn clear(&mut self) -> u16 {
        let n = self.len().0;
        self.entries.clear();
        self.dropped = 0;
        n
    }
}

impl<const N: usize> EventSink for RamLog<N> {
    fn append(&mut self, e: LogEntry) {
        if self.entries.is_full() {
            let _ = self.entries.pop_front();
            self.dropped = self.dropped.saturating_add(1);
        }
        let _ = self.entries.push_back(e);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use shimmy_core::estimator::fusion::MarginReport;
    use shimmy_core::estimator::monitor::{Level, MonitorInput, MonitorParams};

    fn fault(t_ms: u32) -> LogEntry {
        LogEntry::Fault(FaultEvent {
            t_ms,
            kind: 0,
            latched: false,
        })
    }

    #[test]
    fn the_ram_log_drops_the_oldest_and_counts_it() {
        let mut log = RamLog::<3>::new();
        for t in 0..5 {
            log.append(fault(t));
        }
        assert_eq!(log.len(), (3, 2));
        assert_eq!(log.get(0), Some(fault(2)));
        assert_eq!(log.get(2), Some(fault(4)));
        assert_eq!(log.get(3), None);
        assert_eq!(log.clear(), 3);
        assert_eq!(log.len(), (0, 0));
    }

    #[test]
    fn the_open_episode_is_read_as_the_last_entry() {
        let mut log = RamLog::<3>::new();
        log.append(fault(1));
        let open = ShimmyEvent {
            start_s: 2.0,
            speed_mps: 9.0,
            freq_hz: 6.0,
            peak_amplitude_rad: 0.01,
            duration_s: 0.5,
            shimmy_s: 0.0,
            level: 2,
            open: true,
            peak_current_a: 1.0,
            mean_current_a: 0.5,
        };
        let mut page = heapless::Vec::new();
        assert_eq!(log.page(None, &mut Pager::new(1, &mut page)), (1, 0));
        assert!(page.is_empty());
        assert_eq!(log.page(Some(open), &mut Pager::new(0, &mut page)), (2, 0));
        assert_eq!(page[..], [fault(1), LogEntry::Shimmy(open)]);
        assert_eq!(log.page(Some(open), &mut Pager::new(1, &mut page)), (2, 0));
        assert_eq!(page[..], [LogEntry::Shimmy(open)]);
        log.page(Some(open), &mut Pager::new(2, &mut page));
        assert!(page.is_empty());
    }

    #[test]
    fn each_newly_active_fault_is_one_entry() {
        let mut r = Recorder::new();
        let mut log = RamLog::<8>::new();
        let left_flag = 1 << fault_code(FaultKind::LeftFlag);
        let coil_short = 1 << fault_code(FaultKind::CoilShort);
        r.on_faults(10, left_flag, 0, &mut log);
        r.on_faults(20, left_flag, 0, &mut log); // still active: nothing new
        r.on_faults(30, left_flag | coil_short, coil_short, &mut log);
        r.on_faults(40, 0, coil_short, &mut log);
        r.on_faults(50, left_flag, 0, &mut log); // raised again
        r.on_faults(60, left_flag, left_flag, &mut log); // escalated: latched while active
        r.on_faults(70, left_flag, left_flag, &mut log);
        let kinds: std::vec::Vec<_> = (0..log.len().0)
            .filter_map(|i| match log.get(i) {
                Some(LogEntry::Fault(f)) => Some((f.t_ms, f.kind, f.latched)),
                _ => None,
            })
            .collect();
        assert_eq!(
            kinds,
            [
                (10, fault_code(FaultKind::LeftFlag), false),
                (30, fault_code(FaultKind::CoilShort), true),
                (50, fault_code(FaultKind::LeftFlag), false),
                (60, fault_code(FaultKind::LeftFlag), true),
            ]
        );
        // After a reset that restored a latched fault: not logged again.
        let mut r = Recorder::after_boot(coil_short);
        let mut log = RamLog::<8>::new();
        r.on_faults(10, coil_short, coil_short, &mut log);
        assert!(log.is_empty());
    }

    /// A monitor driven through one shimmy episode by amplitude alone: the recorder logs it
    /// once, when it closes, with the commands given while it was open.
    #[test]
    fn a_closed_episode_is_logged_once_with_the_controller_action() {
        let params = MonitorParams::default();
        let mut m = Monitor::<4>::new(params);
        let report = MarginReport::default();
        let mut r = Recorder::new();
        let mut log = RamLog::<8>::new();
        let mut open_seen = None;
        for k in 0..400u32 {
            let t = f64::from(k) * 0.01;
            let shimmy = (100..200).contains(&k);
            let amp = if shimmy { 2.0 * params.amp_on_rad } else { 0.0 };
            // The controller answers the shimmy with 1.5 A, otherwise 0.2 A.
            for _ in 0..10 {
                r.on_command(if shimmy { 1.5 } else { 0.2 });
            }
            m.update(&MonitorInput {
                t_s: t,
                amplitude_rad: amp,
                report: &report,
                speed_margin_sigma_mps: 0.0,
            });
            r.on_update(&m, &mut log);
            if k == 150 {
                open_seen = r.open_event(&m);
            }
        }
        let open = open_seen.expect("episode open at step 150");
        assert!(open.open && open.level == level_code(Level::ShimmyPresent));
        assert_eq!(log.len().0, 1, "one episode, logged once");
        let Some(LogEntry::Shimmy(e)) = log.get(0) else {
            panic!("not a shimmy entry");
        };
        assert!(!e.open);
        assert_eq!(e.level, level_code(Level::ShimmyPresent));
        assert!((e.start_s - 1.0).abs() < 0.011, "{}", e.start_s);
        assert_eq!(e.peak_current_a, 1.5);
        // Mostly 1.5 A, plus the 0.2 A of the release time after the shimmy.
        assert!(e.mean_current_a > 0.2 && e.mean_current_a <= 1.5);
        assert!(r.open_event(&m).is_none());
    }

    /// The watch logs a diagnosis once when it appears, again only when another part is
    /// named, and once when every part is back within its band; an unchanged diagnosis logs
    /// nothing.
    #[test]
    fn a_diagnosis_is_logged_when_it_names_another_part() {
        let est = |factor: f64| ParamEstimate {
            field: "k_d",
            what: "steering linkage stiffness",
            factor,
            sigma_ln: 0.02,
            prior_sigma_ln: 0.15,
            band: (0.7, 1.3),
            out_of_band: true,
        };
        let mut w = DiagnosisWatch::default();
        assert_eq!(w.on_update(0, None), None, "nothing named, nothing logged");
        let e = w
            .on_update(1000, Some((2, est(0.5))))
            .expect("a new diagnosis");
        assert_eq!((e.t_ms, e.param), (1000, Some(2)));
        assert_eq!((e.factor, e.band_low, e.band_high), (0.5, 0.7, 1.3));
        assert_eq!(
            w.on_update(2000, Some((2, est(0.48)))),
            None,
            "the same part"
        );
        let e = w
            .on_update(3000, Some((0, est(1.6))))
            .expect("another part");
        assert_eq!(e.param, Some(0));
        let e = w.on_update(4000, None).expect("resolved");
        assert_eq!((e.param, e.factor), (None, 0.0));
        assert_eq!(w.on_update(5000, None), None);
    }
}

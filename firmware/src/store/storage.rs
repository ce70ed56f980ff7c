//! The store itself: the configuration queue and the event-log queue on one gated flash (the
//! module documentation of `store` says what and why).

use super::flash::FlashError;
use super::log::{self, BootEvent, LogEntry, Unreadable, ENTRY_MAX_BYTES};
use super::standstill::Standstill;
use crate::fault_memory::ResetCause;
use crate::monitoring::ImageVehicle;
use core::future::Future;
use core::ops::Range;
use core::pin::pin;
use core::task::{Context, Poll, Waker};
use embedded_storage_async::nor_flash::{ErrorType, NorFlash, ReadNorFlash};
use sequential_storage::cache::{Cache, Uncached};
use sequential_storage::queue::{QueueConfig, QueueStorage};
use shimmy_core::vehicle::{
    decode_record, encode_record, BoardVehicle, RecordError, RecordVehicle, RECORD_MAX_BYTES,
};

/// Log entries kept in RAM while an append waits for a standstill erase.
pub const PENDING: usize = 16;
/// Bytes `sequential-storage` writes in front of each item (its length, the length's CRC, the
/// data's CRC), for [`Store::log_capacity`].
pub const ITEM_HEADER_BYTES: usize = 8;
/// Bytes of a configuration state before its vehicle record: the boot count (u32,
/// little-endian) and the clearing mark (1 while a log clear is under way, so a clear cut by a
/// power loss is finished at the next boot: a half-erased log page is not left for the queue).
pub const STATE_HEADER_BYTES: usize = 5;
/// Where the clearing mark is in a configuration state (the boot count is in front of it).
const CLEARING_AT: usize = 4;
/// The largest configuration state: the header and the largest vehicle record.
pub const STATE_MAX_BYTES: usize = STATE_HEADER_BYTES + RECORD_MAX_BYTES;

/// The store keeps no cache: every operation scans its pages (entries are rare, and a cache
/// would have to follow every power cut).
type NoCache<K> = Cache<Uncached, Uncached, Uncached, K>;

/// Runs a future of the store to completion. The flashes here never return `Pending`, so this
/// loop polls once per future; it needs no executor and no waker.
pub fn block_on<T>(fut: impl Future<Output = T>) -> T {
    let mut fut = pin!(fut);
    let mut cx = Context::from_waker(Waker::noop());
    loop {
        if let Poll::Ready(v) = fut.as_mut().poll(&mut cx) {
            return v;
        }
    }
}

/// A flash whose erase is refused unless opened by `Gated::open`, which only the store's
/// standstill operations call (each takes the [`Standstill`] token). Writes always go
/// through: programming a few bytes stalls the flash for microseconds, an erase of a 128 KiB
/// sector for over a second.
pub struct Gated<F> {
    flash: F,
    /// Set only by `Gated::open` and by `Store::boot` (before the control loop starts).
    erase_open: bool,
}

impl<F> Gated<F> {
    /// Closed (no erase).
    const fn new(flash: F) -> Self {
        Gated {
            flash,
            erase_open: false,
        }
    }

    /// Opens the erase for the standstill operations of the store.
    fn open(&mut self, _token: &Standstill<'_>) {
        self.erase_open = true;
    }

    /// Closes it again.
    fn close(&mut self) {
        self.erase_open = false;
    }

    /// The flash, without the gate.
    fn into_inner(self) -> F {
        self.flash
    }

    /// The flash under the gate.
    pub fn inner(&self) -> &F {
        &self.flash
    }

    /// The flash under the gate, mutable (tests arm power cuts with it).
    pub fn inner_mut(&mut self) -> &mut F {
        &mut self.flash
    }
}

impl<F: ErrorType<Error = FlashError>> ErrorType for Gated<F> {
    type Error = FlashError;
}

impl<F: ReadNorFlash<Error = FlashError>> ReadNorFlash for Gated<F> {
    const READ_SIZE: usize = F::READ_SIZE;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), FlashError> {
        self.flash.read(offset, bytes).await
    }

    fn capacity(&self) -> usize {
        self.flash.capacity()
    }
}

impl<F: NorFlash<Error = FlashError>> NorFlash for Gated<F> {
    const WRITE_SIZE: usize = F::WRITE_SIZE;
    const ERASE_SIZE: usize = F::ERASE_SIZE;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), FlashError> {
        if !self.erase_open {
            return Err(FlashError::EraseRefused);
        }
        self.flash.erase(from, to).await
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), FlashError> {
        self.flash.write(offset, bytes).await
    }
}

/// Where the configuration queue and the event log lie in the flash (offsets, whole erase
/// units; the configuration needs at least two, so a page turn never erases the newest state).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Layout {
    /// The configuration queue.
    pub config: Range<u32>,
    /// The event-log queue.
    pub log: Range<u32>,
}

impl Layout {
    /// The first `config_pages` erase units of `page` bytes for the configuration, the next
    /// `log_pages` for the log.
    pub const fn split(page: u32, config_pages: u32, log_pages: u32) -> Layout {
        Layout {
            config: 0..config_pages * page,
            log: config_pages * page..(config_pages + log_pages) * page,
        }
    }
}

/// Why a store operation failed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum StoreError {
    /// The flash failed (a power cut, an erase outside standstill, the device).
    Flash(FlashError),
    /// No room, even after dropping what may be dropped.
    Full,
    /// The store found its flash corrupted beyond its own repair.
    Corrupted,
    /// The layout does not fit the flash's geometry (or two ranges overlap).
    Layout,
    /// The vehicle could not be written as a record (it fails its validation).
    Record(RecordError),
    /// Any other error of the store library (a bug there: reported, not hidden).
    Library,
}

impl From<sequential_storage::Error<FlashError>> for StoreError {
    fn from(e: sequential_storage::Error<FlashError>) -> Self {
        use sequential_storage::Error as E;
        match e {
            E::Storage { value, .. } => StoreError::Flash(value),
            E::FullStorage => StoreError::Full,
            E::Corrupted { .. } => StoreError::Corrupted,
            _ => StoreError::Library,
        }
    }
}

/// Where the configuration in use came from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ConfigSource {
    /// The stored record.
    Stored,
    /// No record stored: the compiled-in defaults.
    Missing,
    /// The flash could not be read: the defaults.
    Unreadable(StoreError),
    /// A record is stored but refused (another schema, wrong length, a value out of range):
    /// the defaults.
    Rejected(RecordError),
}

/// The configuration to run with, and where it came from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ConfigLoad {
    /// The vehicle (the stored one, or the image's compiled-in one,
    /// [`BoardVehicle::compiled_in`]).
    pub vehicle: ImageVehicle,
    /// Why this one.
    pub source: ConfigSource,
}

impl ConfigLoad {
    /// The defaults are in use instead of a stored configuration: a fault to report (the issue:
    /// a missing, corrupt or invalid record means the compiled-in defaults plus a fault).
    pub fn is_fault(&self) -> bool {
        self.source != ConfigSource::Stored
    }
}

/// What became of an appended entry.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Appended {
    /// In flash.
    Written,
    /// Kept in RAM until the next standstill (the log needs an erase first).
    Pending,
}

/// What one standstill maintenance did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Maintenance {
    /// Pending entries written.
    pub written: u32,
    /// The boot count was written.
    pub boots_saved: bool,
}

/// What [`Store::boot`] found and did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BootReport {
    /// The configuration to run with.
    pub config: ConfigLoad,
    /// This boot, as logged.
    pub entry: BootEvent,
    /// Entries in the log before this boot's (0 if it could not be read).
    pub log_entries: usize,
}

/// The store after [`Store::boot`], and what the boot found.
pub struct Boot<F> {
    /// The store, ready for the running firmware.
    pub store: Store<F>,
    /// What the boot found and did.
    pub report: BootReport,
}

/// The configuration and the event log on one flash (see the module documentation).
pub struct Store<F> {
    flash: Gated<F>,
    layout: Layout,
    pending: heapless::Deque<LogEntry, PENDING>,
    lost: u32,
    boots_unsaved: Option<u32>,
}

impl<F: NorFlash<Error = FlashError>> Store<F> {
    /// The store on `flash` with `layout`; refused when the layout does not fit the flash.
    fn new(flash: F, layout: Layout) -> Result<Self, StoreError> {
        let fits = |r: &Range<u32>| r.end as usize <= flash.capacity();
        let apart = layout.config.end <= layout.log.start || layout.log.end <= layout.config.start;
        let two_pages =
            layout.config.end.saturating_sub(layout.config.start) >= 2 * F::ERASE_SIZE as u32;
        if !(fits(&layout.config) && fits(&layout.log) && apart && two_pages)
            || QueueConfig::<Gated<F>>::try_new(layout.config.clone()).is_err()
            || QueueConfig::<Gated<F>>::try_new(layout.log.clone()).is_err()
        {
            return Err(StoreError::Layout);
        }
        Ok(Store {
            flash: Gated::new(flash),
            layout,
            pending: heapless::Deque::new(),
            lost: 0,
            boots_unsaved: None,
        })
    }

    /// The flash (tests arm power cuts with it).
    pub fn flash_mut(&mut self) -> &mut F {
        self.flash.inner_mut()
    }

    /// The flash.
    pub fn flash(&self) -> &F {
        self.flash.inner()
    }

    /// Gives the flash back.
    pub fn into_flash(self) -> F {
        self.flash.into_inner()
    }

    /// Entries the log holds at least: every page but the one a full queue erases for new
    /// entries, filled with the longest entry and `sequential-storage`'s item header (a
    /// length, its CRC and the data's CRC: [`ITEM_HEADER_BYTES`]).
    pub fn log_capacity(&self) -> u16 {
        let pages = (self.layout.log.end - self.layout.log.start) as usize / F::ERASE_SIZE;
        let per_page = F::ERASE_SIZE / (ENTRY_MAX_BYTES + ITEM_HEADER_BYTES);
        u16::try_from(pages.saturating_sub(1) * per_page).unwrap_or(u16::MAX)
    }

    /// Entries lost because more than [`PENDING`] waited for a standstill.
    pub fn lost_entries(&self) -> u32 {
        self.lost
    }

    /// Something waits for a standstill (pending entries, the boot count).
    pub fn needs_maintenance(&self) -> bool {
        !self.pending.is_empty() || self.boots_unsaved.is_some()
    }

    /// Entries waiting in RAM for a standstill.
    pub fn pending_entries(&self) -> usize {
        self.pending.len()
    }

    /// Opens the store at boot, before the control loop and the watchdog start: repairs what a
    /// power cut interrupted (the only erase outside standstill, see the module
    /// documentation), loads the configuration, counts the boot and logs it (`cause` and
    /// `resets_since_power_on` from the fault memory). Refused only when the layout does not
    /// fit the flash; a flash it cannot read gives the defaults ([`ConfigLoad`]).
    pub fn boot(
        flash: F,
        layout: Layout,
        cause: ResetCause,
        resets_since_power_on: u32,
    ) -> Result<Boot<F>, StoreError> {
        let mut store = Store::new(flash, layout)?;
        store.flash.erase_open = true;
        let config = store.load_config();
        let mut state = [0u8; STATE_MAX_BYTES];
        if let Ok(n) = store.read_state(&mut state) {
            if n > 0 && state_clearing(&state) {
                // A clear was cut by a power loss: finish it.
                let _ = store.clear_open();
            }
        }
        // Reading the whole log finishes an interrupted page turn of the queue.
        let log_entries = store.read_log(&mut |_| ()).unwrap_or(0);
        let entry = store.record_boot(cause, resets_since_power_on);
        store.flash.close();
        Ok(Boot {
            store,
            report: BootReport {
                config,
                entry,
                log_entries,
            },
        })
    }

    /// The vehicle to run with (never fails; see [`ConfigLoad`]).
    pub fn load_config(&mut self) -> ConfigLoad {
        let nominal = |source| ConfigLoad {
            vehicle: ImageVehicle::compiled_in(),
            source,
        };
        let mut state = [0u8; STATE_MAX_BYTES];
        match self.read_state(&mut state) {
            Ok(n) => match state.get(STATE_HEADER_BYTES..n) {
                Some(record) if !record.is_empty() => match decode_record::<ImageVehicle>(record) {
                    Ok(vehicle) => ConfigLoad {
                        vehicle,
                        source: ConfigSource::Stored,
                    },
                    Err(e) => nominal(ConfigSource::Rejected(e)),
                },
                _ => nominal(ConfigSource::Missing),
            },
            Err(e) => nominal(ConfigSource::Unreadable(e)),
        }
    }

    /// The configuration queue: the log's queue type on the other range, so its code is in
    /// the image once.
    fn config_queue(&mut self) -> Result<QueueStorage<&mut Gated<F>, NoCache<()>>, StoreError> {
        let config =
            QueueConfig::try_new(self.layout.config.clone()).map_err(|_| StoreError::Layout)?;
        Ok(QueueStorage::new(
            &mut self.flash,
            config,
            Cache::new_uncached(),
        ))
    }

    /// The newest configuration state into `out`; its length, 0 when none is stored. Each
    /// state is one queue item with its CRC: one cut by a power loss does not read back, and
    /// the one before it is the newest.
    fn read_state(&mut self, out: &mut [u8; STATE_MAX_BYTES]) -> Result<usize, StoreError> {
        let mut queue = self.config_queue()?;
        let mut iter = block_on(queue.iter())?;
        let mut buf = [0u8; STATE_MAX_BYTES + 8];
        let mut len = 0;
        while let Some(item) = block_on(iter.next(&mut buf))? {
            if let Some(dst) = out.get_mut(..item.len()) {
                if item.len() >= STATE_HEADER_BYTES {
                    dst.copy_from_slice(&item);
                    len = item.len();
                }
            }
        }
        Ok(len)
    }

    /// Writes a new configuration state: the newest one with `change` applied, appended whole
    /// (the oldest page is erased when the queue is full; the newest state is never on it).
    /// Refused when the newest state cannot be read, so a write never drops what it could not
    /// read. Needs the erase open (boot or a standstill token).
    fn update_state(
        &mut self,
        change: impl FnOnce(&mut [u8; STATE_MAX_BYTES], usize) -> Result<usize, StoreError>,
    ) -> Result<(), StoreError> {
        let mut state = [0u8; STATE_MAX_BYTES];
        // none stored: boot count 0, no clear under way, no vehicle record
        let n = self.read_state(&mut state)?.max(STATE_HEADER_BYTES);
        let n = change(&mut state, n)?;
        let bytes = state.get(..n).ok_or(StoreError::Library)?;
        let mut queue = self.config_queue()?;
        block_on(queue.push(bytes, true)).map_err(StoreError::from)
    }

    /// Sets the boot count of the configuration state.
    fn store_boots(&mut self, count: u32) -> Result<(), StoreError> {
        self.update_state(|state, n| {
            if let Some(boots) = state.first_chunk_mut() {
                *boots = count.to_le_bytes();
            }
            Ok(n)
        })
    }

    /// Sets or clears the clearing mark of the configuration state.
    fn store_clearing(&mut self, clearing: bool) -> Result<(), StoreError> {
        self.update_state(|state, n| {
            if let Some(mark) = state.get_mut(CLEARING_AT) {
                *mark = u8::from(clearing);
            }
            Ok(n)
        })
    }

    /// Writes `vehicle` as the configuration (validated first: an invalid vehicle is refused
    /// and nothing is written). Atomic: after a power cut the board has the old or the new one.
    pub fn save_config(
        &mut self,
        vehicle: &ImageVehicle,
        token: &Standstill<'_>,
    ) -> Result<(), StoreError> {
        vehicle
            .check_all()
            .map_err(|e| StoreError::Record(RecordError::Invalid(e)))?;
        self.flash.open(token);
        let result = self.store_record(|record| encode_record(vehicle, record));
        self.flash.close();
        result
    }

    /// Replaces the vehicle record of the configuration state with what `encode` writes into
    /// the record bytes (its length; the state's header is kept).
    fn store_record(
        &mut self,
        encode: impl FnOnce(&mut [u8]) -> Result<usize, RecordError>,
    ) -> Result<(), StoreError> {
        self.update_state(|state, _| {
            let record = state
                .get_mut(STATE_HEADER_BYTES..)
                .ok_or(StoreError::Library)?;
            let n = encode(record).map_err(StoreError::Record)?;
            Ok(STATE_HEADER_BYTES + n)
        })
    }

    /// Counts this boot (the persistent count) and logs it with the reset cause and the fault
    /// memory's reset count; what cannot be written now is written at the next standstill.
    fn record_boot(&mut self, cause: ResetCause, resets_since_power_on: u32) -> BootEvent {
        let mut state = [0u8; STATE_MAX_BYTES];
        let stored = match self.read_state(&mut state) {
            Ok(n) if n > 0 => state_boots(&state),
            _ => 0,
        };
        let boot_count = stored.saturating_add(1);
        if self.store_boots(boot_count).is_err() {
            self.boots_unsaved = Some(boot_count);
        }
        let entry = BootEvent {
            cause: cause as u8,
            resets_since_power_on,
            boot_count,
        };
        self.append(&LogEntry::Boot(entry));
        entry
    }

    fn queue(&mut self) -> Result<QueueStorage<&mut Gated<F>, NoCache<()>>, StoreError> {
        let config =
            QueueConfig::try_new(self.layout.log.clone()).map_err(|_| StoreError::Layout)?;
        Ok(QueueStorage::new(
            &mut self.flash,
            config,
            Cache::new_uncached(),
        ))
    }

    fn push(&mut self, entry: &LogEntry, drop_oldest: bool) -> Result<(), StoreError> {
        let mut bytes = [0u8; ENTRY_MAX_BYTES];
        let n = log::encode(entry, &mut bytes);
        let data = bytes.get(..n).ok_or(StoreError::Library)?;
        let mut queue = self.queue()?;
        block_on(queue.push(data, drop_oldest)).map_err(StoreError::from)
    }

    /// Appends `entry` to the log without erasing: in flash when there is erased room, else in
    /// RAM until the next [`Self::maintain`] (the oldest pending entry is lost, and counted,
    /// when more than [`PENDING`] wait). Order is kept: while entries wait, new ones queue
    /// behind them.
    pub fn append(&mut self, entry: &LogEntry) -> Appended {
        if self.pending.is_empty() && self.push(entry, false).is_ok() {
            return Appended::Written;
        }
        if self.pending.is_full() {
            let _ = self.pending.pop_front();
            self.lost = self.lost.saturating_add(1);
        }
        let _ = self.pending.push_back(*entry);
        Appended::Pending
    }

    /// At standstill: writes the pending entries (dropping the oldest of the log where it is
    /// full) and the unsaved boot count. Stops at the first failure (a power cut); what was not
    /// written stays pending.
    pub fn maintain(&mut self, token: &Standstill<'_>) -> Result<Maintenance, StoreError> {
        self.flash.open(token);
        let result = self.maintain_open();
        self.flash.close();
        result
    }

    fn maintain_open(&mut self) -> Result<Maintenance, StoreError> {
        let mut done = Maintenance::default();
        while let Some(entry) = self.pending.front().copied() {
            self.push(&entry, true)?;
            let _ = self.pending.pop_front();
            done.written += 1;
        }
        if let Some(count) = self.boots_unsaved {
            self.store_boots(count)?;
            self.boots_unsaved = None;
            done.boots_saved = true;
        }
        Ok(done)
    }

    /// Calls `each` with every entry of the log, oldest first (entries still pending in RAM
    /// last); returns how many. Reads only. (`dyn`: one copy of the queue walk in the image
    /// for its callers, the boot, the link's pages and its clear; entries by reference: each
    /// is copied once, by the caller that keeps it.)
    #[inline(never)]
    pub fn read_log(
        &mut self,
        each: &mut dyn FnMut(Result<&LogEntry, Unreadable>),
    ) -> Result<usize, StoreError> {
        let mut count = 0;
        let config =
            QueueConfig::try_new(self.layout.log.clone()).map_err(|_| StoreError::Layout)?;
        let mut queue = QueueStorage::new(&mut self.flash, config, Cache::new_uncached());
        let mut iter = block_on(queue.iter())?;
        let mut buf = [0u8; ENTRY_MAX_BYTES + 8];
        while let Some(item) = block_on(iter.next(&mut buf))? {
            each(log::decode(&item).as_ref().map_err(|u| *u));
            count += 1;
        }
        for e in &self.pending {
            each(Ok(e));
            count += 1;
        }
        Ok(count)
    }

    /// Empties the log (flash and pending entries). The configuration stays.
    pub fn clear_log(&mut self, token: &Standstill<'_>) -> Result<(), StoreError> {
        self.flash.open(token);
        let result = self.clear_open();
        self.flash.close();
        if result.is_ok() {
            self.pending.clear();
        }
        result
    }

    /// The clear with the erase open: mark, erase, unmark (a cut in between: finished at boot).
    fn clear_open(&mut self) -> Result<(), StoreError> {
        self.store_clearing(true)?;
        let mut queue = self.queue()?;
        block_on(queue.erase_all()).map_err(StoreError::from)?;
        self.store_clearing(false)
    }
}

/// The clearing mark of a configuration state.
fn state_clearing(state: &[u8; STATE_MAX_BYTES]) -> bool {
    state.get(CLEARING_AT) == Some(&1)
}

/// The boot count of a configuration state.
fn state_boots(state: &[u8; STATE_MAX_BYTES]) -> u32 {
    state.first_chunk().map_or(0, |b| u32::from_le_bytes(*b))
}

#[cfg(test)]
#[path = "tests.rs"]
mod tests;

//! The board's memory in flash: the vehicle configuration and the event log, safe against power
//! cuts.
//!
//! - Configuration: the core's vehicle record ([`Vehicle::encode_record`](shimmy_core::vehicle::Vehicle::encode_record): schema id over the
//!   field table, every field as an f64, validated whole by [`Vehicle::decode_record`](shimmy_core::vehicle::Vehicle::decode_record))
//!   behind the persistent boot count and the log's clearing mark ([`STATE_HEADER_BYTES`]): one
//!   configuration state, appended whole to a `sequential-storage` queue whenever a part of it
//!   changes. An item is written with a CRC and the newest valid one wins, so after a power cut
//!   at any byte of a write the board reads the old or the new record; the page a full queue
//!   erases never holds the newest state (two pages at least). The log's queue type, so its
//!   code is in the image once.
//!   [`Store::load_config`] never fails: a missing, unreadable or invalid record gives the
//!   compiled-in vehicle ([`BoardVehicle::compiled_in`](shimmy_core::vehicle::BoardVehicle::compiled_in): the car's `Vehicle::nominal`, the truck image's `truck-full`) and says why ([`ConfigSource`]), so the caller can report
//!   it as a fault; nothing is half-applied.
//! - Event log: the host link's [`LogEntry`]s (shimmy episodes, faults raised or latched,
//!   boots) in a `sequential-storage` queue, oldest first; when it is full the oldest go first.
//!   The link serves this log (`crate::link`), so events from before a reset can be read.
//! - Erase only at standstill: all flash access goes through [`Gated`], whose
//!   erase is refused unless a [`Standstill`] token opened it for one of [`Store::maintain`],
//!   [`Store::save_config`] or [`Store::clear_log`]. An append that would need an erase (the
//!   queue moving onto a used page) is kept in RAM ([`PENDING`] entries) and written by the
//!   next [`Store::maintain`]: those few entries are the only ones a power cut before the next
//!   standstill can lose.
//! - The one other place the gate opens is [`Store::boot`], before the control loop and the
//!   watchdog start (the coil is off until then): a power cut during a standstill write can
//!   leave a page turn half done, and `sequential-storage` finishes it (an erase) before it
//!   reads again. Boot is also where the board learns its configuration, so the repair has to
//!   happen there for "old or new, never a mix" to hold.
//!
//! `sequential-storage` is async; the flashes here complete every operation at once, so
//! [`block_on`] polls each future to completion without an executor. The store runs in the
//! firmware's background loop, which every task preempts.

pub mod drive;
mod flash;
mod log;
mod standstill;
mod storage;
#[cfg(target_os = "none")]
pub mod target;
mod task;

#[cfg(target_os = "none")]
pub use flash::board;
pub use flash::{FlashError, RamFlash};
pub use log::{
    decode, encode, BootEvent, FaultEvent, LogEntry, ShimmyEvent, Unreadable, ENTRY_MAX_BYTES,
};
pub use standstill::{
    Standstill, StandstillWatch, IDLE_CURRENT_A, STANDSTILL_HOLD_S, STANDSTILL_SPEED_MPS,
};
pub use storage::{
    block_on, Appended, Boot, BootReport, ConfigLoad, ConfigSource, Gated, Layout, Maintenance,
    Store, StoreError, ITEM_HEADER_BYTES, PENDING, STATE_HEADER_BYTES, STATE_MAX_BYTES,
};
pub use task::{Motion, Pass, StoreTask, RETRY_S};

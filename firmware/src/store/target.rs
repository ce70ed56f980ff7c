//! The store's flash on the target: the internal flash's sectors 8-11 on the board, a RAM
//! flash under QEMU (whose flash cannot be written) in RAM that a reset leaves alone, so the
//! log survives a simulated reset.

use super::storage::{BootReport, Layout, Store, StoreError};
use super::task::StoreTask;
use crate::fault_memory::ResetCause;
use core::sync::atomic::{AtomicBool, Ordering};

/// The flash the store runs on in this build.
#[cfg(not(feature = "qemu"))]
pub type TargetFlash = super::flash::board::BoardFlash;
/// The flash the store runs on in this build.
#[cfg(feature = "qemu")]
pub type TargetFlash = &'static mut qemu::QemuFlash;

/// The store's layout on the board: the configuration in sectors 8-9, the log in 10-11.
#[cfg(not(feature = "qemu"))]
pub const LAYOUT: Layout = Layout::split(super::flash::board::SECTOR_BYTES as u32, 2, 2);
/// The store's layout under QEMU: the same split over 16 KiB sectors.
#[cfg(feature = "qemu")]
pub const LAYOUT: Layout = Layout::split(qemu::SECTOR_BYTES as u32, 2, 2);

static TAKEN: AtomicBool = AtomicBool::new(false);

/// The flash, once (`None` on a second call). `ram_lost`: the RAM did not survive (a power-on,
/// as the fault memory found it); the QEMU flash is then formatted (a new chip).
fn take(ram_lost: bool) -> Option<TargetFlash> {
    if TAKEN.swap(true, Ordering::AcqRel) {
        return None;
    }
    #[cfg(not(feature = "qemu"))]
    {
        let _ = ram_lost;
        // SAFETY: taken once (above). The rest of the firmware never uses the FLASH block
        // except the HAL's clock set-up, which only writes the wait states (FLASH_ACR); the
        // store uses the key, status and control registers.
        let flash = unsafe { stm32f4xx_hal::pac::FLASH::steal() };
        Some(super::flash::board::BoardFlash::new(flash))
    }
    #[cfg(feature = "qemu")]
    {
        Some(qemu::flash(ram_lost))
    }
}

/// Opens the store at boot (before `board::init` starts the watchdog: see `Store::boot`)
/// and wraps it for the background loop.
pub fn boot(
    ram_lost: bool,
    cause: ResetCause,
    resets_since_power_on: u32,
) -> Result<(StoreTask<TargetFlash>, BootReport), StoreError> {
    let flash = take(ram_lost).ok_or(StoreError::Layout)?;
    let b = Store::boot(flash, LAYOUT, cause, resets_since_power_on)?;
    Ok((StoreTask::new(b.store), b.report))
}

/// The RAM flash of the QEMU build.
#[cfg(feature = "qemu")]
pub mod qemu {
    use super::super::flash::RamFlash;
    use core::mem::MaybeUninit;

    /// Sector size of the QEMU flash: the F405's 16 KiB sectors (its 128 KiB ones would not
    /// fit QEMU's 128 KiB of RAM four times).
    pub const SECTOR_BYTES: usize = 16 * 1024;
    /// Four sectors, split like the board's.
    pub type QemuFlash = RamFlash<{ 4 * SECTOR_BYTES }, SECTOR_BYTES>;

    #[link_section = ".uninit.shimmy_store_flash"]
    static mut FLASH: MaybeUninit<QemuFlash> = MaybeUninit::uninit();

    /// The flash (called once, by `take`); formatted when `ram_lost`.
    pub(super) fn flash(ram_lost: bool) -> &'static mut QemuFlash {
        // SAFETY: called once (`take`), so this is the only reference; `RamFlash` is integers
        // only (`repr(C)`), so whatever the RAM holds is a valid value.
        let f = unsafe { (*core::ptr::addr_of_mut!(FLASH)).assume_init_mut() };
        if ram_lost {
            f.format();
        }
        f
    }
}

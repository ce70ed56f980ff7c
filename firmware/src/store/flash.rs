//! The flashes under the store: [`RamFlash`] (NOR semantics in RAM, with a power cut at any
//! byte, for host tests, the fuzz target and QEMU, whose flash cannot be written) and, on the
//! board, the STM32F405's internal flash.

use embedded_storage_async::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};

/// Why a flash operation failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(target_os = "none", derive(defmt::Format))]
pub enum FlashError {
    /// Outside the flash.
    OutOfBounds,
    /// Offset or length not a multiple of the write or erase size.
    NotAligned,
    /// A byte written twice without an erase in between (NOR flash cannot do that safely).
    NotErased,
    /// The power went: the operation stopped part-way ([`RamFlash::cut_power_after`]).
    PowerCut,
    /// An erase outside standstill (`Gated`): refused, nothing changed.
    EraseRefused,
    /// The board's flash controller reported an error.
    Device,
}

impl NorFlashError for FlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            FlashError::OutOfBounds => NorFlashErrorKind::OutOfBounds,
            FlashError::NotAligned => NorFlashErrorKind::NotAligned,
            _ => NorFlashErrorKind::Other,
        }
    }
}

/// NOR flash in RAM: `BYTES` bytes in pages (erase units) of `PAGE` bytes, written a byte at a
/// time like the F405's flash at x8 parallelism. An erase sets a page to 0xFF; a write needs
/// erased bytes. A power cut can be armed to stop any write or erase after a given number of
/// bytes: the bytes before it are done, the rest untouched (an interrupted erase leaves the page
/// part old, part erased).
///
/// Integers only (`repr(C)`): every bit pattern is a `RamFlash`, so QEMU can keep one in RAM
/// that start-up leaves alone (`.uninit`) and find it again after a reset.
#[derive(Clone)]
#[repr(C)]
pub struct RamFlash<const BYTES: usize, const PAGE: usize> {
    data: [u8; BYTES],
    /// Bytes until the power cut; [`NEVER`] when none is armed.
    cut_after: u32,
}

/// No power cut armed.
const NEVER: u32 = u32::MAX;

impl<const BYTES: usize, const PAGE: usize> RamFlash<BYTES, PAGE> {
    /// Compile-time check of the geometry (whole pages).
    const GEOMETRY: () = assert!(PAGE > 0 && BYTES.is_multiple_of(PAGE));

    /// An erased flash.
    pub const fn new() -> Self {
        let () = Self::GEOMETRY;
        RamFlash {
            data: [0xFF; BYTES],
            cut_after: NEVER,
        }
    }

    /// The content (for tests and the fuzz target).
    pub fn bytes(&self) -> &[u8] {
        &self.data
    }

    /// Erases everything (a new chip): what QEMU's boot does with the garbage RAM of a power-on.
    pub fn format(&mut self) {
        self.data.fill(0xFF);
        self.cut_after = NEVER;
    }

    /// The power goes after `bytes` more bytes have been written or erased (`None`: never).
    pub fn cut_power_after(&mut self, bytes: Option<u32>) {
        self.cut_after = bytes.map_or(NEVER, |b| b.min(NEVER - 1));
    }

    /// Whether an armed power cut has happened (then every operation fails until re-armed).
    pub fn power_is_cut(&self) -> bool {
        self.cut_after == 0
    }

    fn range(offset: u32, len: usize, align: usize) -> Result<core::ops::Range<usize>, FlashError> {
        let start = offset as usize;
        let end = start.checked_add(len).ok_or(FlashError::OutOfBounds)?;
        if end > BYTES {
            return Err(FlashError::OutOfBounds);
        }
        if !start.is_multiple_of(align) || !len.is_multiple_of(align) {
            return Err(FlashError::NotAligned);
        }
        Ok(start..end)
    }

    /// One byte of work against the power budget.
    fn spend(&mut self) -> Result<(), FlashError> {
        match self.cut_after {
            0 => Err(FlashError::PowerCut),
            NEVER => Ok(()),
            _ => {
                self.cut_after -= 1;
                Ok(())
            }
        }
    }
}

impl<const BYTES: usize, const PAGE: usize> Default for RamFlash<BYTES, PAGE> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const BYTES: usize, const PAGE: usize> ErrorType for RamFlash<BYTES, PAGE> {
    type Error = FlashError;
}

impl<const BYTES: usize, const PAGE: usize> ReadNorFlash for RamFlash<BYTES, PAGE> {
    const READ_SIZE: usize = 1;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), FlashError> {
        if self.power_is_cut() {
            return Err(FlashError::PowerCut);
        }
        let r = Self::range(offset, bytes.len(), 1)?;
        let src = self.data.get(r).ok_or(FlashError::OutOfBounds)?;
        bytes.copy_from_slice(src);
        Ok(())
    }

    fn capacity(&self) -> usize {
        BYTES
    }
}

impl<const BYTES: usize, const PAGE: usize> NorFlash for RamFlash<BYTES, PAGE> {
    const WRITE_SIZE: usize = 1;
    const ERASE_SIZE: usize = PAGE;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), FlashError> {
        let len = (to as usize)
            .checked_sub(from as usize)
            .ok_or(FlashError::OutOfBounds)?;
        let r = Self::range(from, len, PAGE)?;
        for i in r {
            self.spend()?;
            if let Some(b) = self.data.get_mut(i) {
                *b = 0xFF;
            }
        }
        Ok(())
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), FlashError> {
        let r = Self::range(offset, bytes.len(), 1)?;
        for (i, &v) in r.zip(bytes) {
            self.spend()?;
            let b = self.data.get_mut(i).ok_or(FlashError::OutOfBounds)?;
            if *b != 0xFF {
                return Err(FlashError::NotErased);
            }
            *b = v;
        }
        Ok(())
    }
}

/// The STM32F405's internal flash as the store sees it: offsets count from the first storage
/// sector (`__shimmy_store_start` in `memory.x`), erase units are its 128 KiB sectors, writes
/// are byte programs (x8 parallelism, any supply voltage).
#[cfg(target_os = "none")]
pub mod board {
    use crate::store::flash::FlashError;
    use embedded_storage::nor_flash as blocking;
    use embedded_storage_async::nor_flash::{ErrorType, NorFlash, ReadNorFlash};
    use stm32f4xx_hal::flash::{FlashExt, LockedFlash};

    /// Size of the storage area (sectors 8 to 11), bytes.
    pub const STORE_BYTES: usize = 4 * SECTOR_BYTES;
    /// One 128 KiB sector.
    pub const SECTOR_BYTES: usize = 128 * 1024;

    unsafe extern "C" {
        /// First byte of the storage sectors (memory.x).
        static __shimmy_store_start: u8;
    }

    /// The storage sectors of the internal flash.
    pub struct BoardFlash {
        flash: LockedFlash,
        base: u32,
    }

    impl BoardFlash {
        /// The store's sectors of `flash` (offset of `__shimmy_store_start` from the flash base).
        pub fn new(flash: stm32f4xx_hal::pac::FLASH) -> Self {
            let flash = LockedFlash::new(flash);
            // Only the address of the linker symbol is taken, never its content.
            let start = core::ptr::addr_of!(__shimmy_store_start) as usize;
            let base = start.wrapping_sub(flash.address()) as u32;
            BoardFlash { flash, base }
        }

        fn at(&self, offset: u32, len: usize) -> Result<u32, FlashError> {
            if offset as usize + len > STORE_BYTES {
                return Err(FlashError::OutOfBounds);
            }
            Ok(self.base + offset)
        }
    }

    impl ErrorType for BoardFlash {
        type Error = FlashError;
    }

    impl ReadNorFlash for BoardFlash {
        const READ_SIZE: usize = 1;

        async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), FlashError> {
            let at = self.at(offset, bytes.len())?;
            blocking::ReadNorFlash::read(&mut self.flash, at, bytes).map_err(|_| FlashError::Device)
        }

        fn capacity(&self) -> usize {
            STORE_BYTES
        }
    }

    impl NorFlash for BoardFlash {
        const WRITE_SIZE: usize = 1;
        const ERASE_SIZE: usize = SECTOR_BYTES;

        async fn erase(&mut self, from: u32, to: u32) -> Result<(), FlashError> {
            let from_at = self.at(from, 0)?;
            let to_at = self.at(to, 0)?;
            let flash = &mut self.flash;
            crate::periph::with_watchdog_stretched(|| {
                let mut unlocked = flash.unlocked();
                blocking::NorFlash::erase(&mut unlocked, from_at, to_at)
            })
            .map_err(|_| FlashError::Device)
        }

        async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), FlashError> {
            let at = self.at(offset, bytes.len())?;
            let mut unlocked = self.flash.unlocked();
            blocking::NorFlash::write(&mut unlocked, at, bytes).map_err(|_| FlashError::Device)
        }
    }
}

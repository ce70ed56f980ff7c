//! AS5047P-class 14-bit magnetic angle encoder over SPI (`embedded_hal::spi::SpiDevice`).
//!
//! Protocol (16-bit frames, MSB first, chip select released between frames):
//! - command: bit 15 even parity over bits 14..0, bit 14 read (1) / write (0), bits 13..0 address;
//! - response (clocked out during the *next* frame): bit 15 even parity over bits 14..0, bit 14
//!   error flag (the previous frame went wrong), bits 13..0 data.
//!
//! A read is therefore two frames: the command, then a NOP whose response carries the data.
//! When the error flag is set the driver reads (and so clears) ERRFL and returns it.
//!
//! [`AngleTracker`] turns raw 14-bit counts into a continuous angle relative to a calibrated
//! zero: it unwraps across the 0/2pi wrap and rejects steps a wheel cannot make in one sample.

use core::f32::consts::PI;
use embedded_hal::spi::SpiDevice;

/// Counts per revolution of the 14-bit angle.
pub const COUNTS_PER_REV: u16 = 1 << 14;
/// Mask of the 14 data/address bits.
const DATA_MASK: u16 = 0x3FFF;
/// Error-flag bit of a response.
const EF_BIT: u16 = 1 << 14;
/// Read bit of a command.
const READ_BIT: u16 = 1 << 14;

/// Register addresses used by the driver.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u16)]
pub enum Register {
    /// No operation (reads 0); used to clock out the previous command's response.
    Nop = 0x0000,
    /// Error register (cleared by reading): bit 0 framing error, bit 1 invalid command,
    /// bit 2 parity error.
    Errfl = 0x0001,
    /// Diagnostics and automatic gain control.
    Diaagc = 0x3FFC,
    /// Angle with dynamic angle error compensation.
    Anglecom = 0x3FFF,
}

/// Contents of ERRFL, read after a response with the error flag set.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ErrorFlags(pub u16);

impl ErrorFlags {
    /// The sensor saw a framing error (SPI clock count not a multiple of 16).
    pub fn framing(self) -> bool {
        self.0 & 0b001 != 0
    }
    /// The sensor received an invalid command.
    pub fn invalid_command(self) -> bool {
        self.0 & 0b010 != 0
    }
    /// The sensor saw a parity error in our command.
    pub fn parity(self) -> bool {
        self.0 & 0b100 != 0
    }
}

/// Errors of the encoder driver, generic over the SPI bus error.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Error<E> {
    /// The SPI bus reported an error.
    Spi(E),
    /// The response's parity bit does not match its contents (corrupted frame).
    Parity {
        /// The raw response frame.
        frame: u16,
    },
    /// The response's error flag was set; ERRFL was read (and cleared) and holds the cause.
    ErrorFlag(ErrorFlags),
}

/// Even parity over bits 14..0: returns the bit 15 that makes the frame's ones count even.
pub const fn parity_bit(frame: u16) -> u16 {
    ((frame & 0x7FFF).count_ones() as u16) & 1
}

/// A read command frame for `addr` with its parity bit.
pub const fn read_command(addr: u16) -> u16 {
    let f = READ_BIT | (addr & DATA_MASK);
    f | (parity_bit(f) << 15)
}

/// Checks a response frame's parity; returns `(error_flag, data)`.
pub fn decode_response<E>(frame: u16) -> Result<(bool, u16), Error<E>> {
    if parity_bit(frame) != frame >> 15 {
        return Err(Error::Parity { frame });
    }
    Ok((frame & EF_BIT != 0, frame & DATA_MASK))
}

/// The AS5047P driver. Owns its `SpiDevice` (which owns the chip select).
pub struct As5047p<SPI> {
    spi: SPI,
}

impl<SPI: SpiDevice> As5047p<SPI> {
    /// Wraps an SPI device (mode 1: CPOL 0, CPHA 1; up to 10 MHz).
    pub fn new(spi: SPI) -> Self {
        As5047p { spi }
    }

    /// Gives the SPI device back.
    pub fn release(self) -> SPI {
        self.spi
    }

    fn frame(&mut self, word: u16) -> Result<u16, Error<SPI::Error>> {
        let mut buf = word.to_be_bytes();
        self.spi.transfer_in_place(&mut buf).map_err(Error::Spi)?;
        Ok(u16::from_be_bytes(buf))
    }

    /// Reads a register: the command frame, then a NOP frame that clocks out the data.
    /// Checks parity and the error flag; on an error flag reads ERRFL (which clears it).
    pub fn read_register(&mut self, reg: Register) -> Result<u16, Error<SPI::Error>> {
        self.frame(read_command(reg as u16))?;
        let resp = self.frame(read_command(Register::Nop as u16))?;
        let (ef, data) = decode_response(resp)?;
        if ef {
            return Err(Error::ErrorFlag(self.read_errfl()?));
        }
        Ok(data)
    }

    /// Reads and clears ERRFL.
    pub fn read_errfl(&mut self) -> Result<ErrorFlags, Error<SPI::Error>> {
        self.frame(read_command(Register::Errfl as u16))?;
        let resp = self.frame(read_command(Register::Nop as u16))?;
        let (_ef, data) = decode_response(resp)?;
        Ok(ErrorFlags(data))
    }

    /// Reads the compensated 14-bit angle (ANGLECOM), 0..16383 for 0..2pi.
    pub fn read_angle_counts(&mut self) -> Result<u16, Error<SPI::Error>> {
        self.read_register(Register::Anglecom)
    }
}

/// Why a raw count was not accepted by the [`AngleTracker`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TrackError {
    /// The (unwrapped) step since the last accepted sample exceeds the plausible limit.
    Jump {
        /// The step in counts.
        step_counts: i32,
    },
}

/// Continuous angle from 14-bit counts: unwraps across 0/2pi and subtracts a calibrated zero.
#[derive(Clone, Copy, Debug)]
pub struct AngleTracker {
    last_raw: Option<u16>,
    /// Unwrapped position of the last accepted sample in counts.
    unwrapped: i32,
    zero_counts: i32,
    max_step_counts: i32,
}

/// Radians per count.
pub const RAD_PER_COUNT: f32 = 2.0 * PI / COUNTS_PER_REV as f32;

impl AngleTracker {
    /// `zero_counts`: the raw count that is 0 rad (straight ahead, from calibration);
    /// `max_step_counts`: the largest plausible change between two samples (must be below half a
    /// turn, 8192, or unwrapping becomes ambiguous).
    pub const fn new(zero_counts: u16, max_step_counts: u16) -> Self {
        let max = if max_step_counts > 8191 {
            8191
        } else {
            max_step_counts
        };
        AngleTracker {
            last_raw: None,
            unwrapped: 0,
            zero_counts: (zero_counts & DATA_MASK) as i32,
            max_step_counts: max as i32,
        }
    }

    /// Feeds one raw sample; returns the continuous angle in rad. A rejected sample leaves the
    /// state unchanged (the next sample is compared with the last accepted one).
    pub fn update(&mut self, raw: u16) -> Result<f32, TrackError> {
        let raw = raw & DATA_MASK;
        match self.last_raw {
            None => {
                // First sample: choose the turn that puts it nearest to the zero.
                self.unwrapped = self.zero_counts + wrap_step(raw as i32 - self.zero_counts);
            }
            Some(last) => {
                let step = wrap_step(raw as i32 - last as i32);
                if step.abs() > self.max_step_counts {
                    return Err(TrackError::Jump { step_counts: step });
                }
                self.unwrapped += step;
            }
        }
        self.last_raw = Some(raw);
        Ok(self.angle_rad())
    }

    /// The angle of the last accepted sample relative to the zero, in rad.
    pub fn angle_rad(&self) -> f32 {
        (self.unwrapped - self.zero_counts) as f32 * RAD_PER_COUNT
    }

    /// Makes the last accepted sample the new zero (calibration, wheels straight ahead).
    pub fn calibrate_zero_here(&mut self) {
        if let Some(raw) = self.last_raw {
            self.zero_counts = raw as i32;
            self.unwrapped = raw as i32;
        }
    }
}

/// Wraps a count difference into [-8192, 8191].
fn wrap_step(d: i32) -> i32 {
    let n = COUNTS_PER_REV as i32;
    (d + n / 2).rem_euclid(n) - n / 2
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_hal_mock::eh1::spi::{Mock, Transaction};

    /// A response frame with correct parity, built independently of `parity_bit` (by counting
    /// bits one at a time).
    fn response(ef: bool, data: u16) -> u16 {
        let f = (u16::from(ef) << 14) | (data & 0x3FFF);
        let mut ones = 0;
        for i in 0..15 {
            ones += (f >> i) & 1;
        }
        f | ((ones % 2) << 15)
    }

    fn frame(cmd: u16, resp: u16) -> Vec<Transaction<u8>> {
        vec![
            Transaction::transaction_start(),
            Transaction::transfer_in_place(cmd.to_be_bytes().to_vec(), resp.to_be_bytes().to_vec()),
            Transaction::transaction_end(),
        ]
    }

    #[test]
    fn command_frames_match_the_datasheet() {
        // Datasheet examples: read ANGLECOM = 0xFFFF, read NOP = 0xC000, read ERRFL = 0x4001.
        assert_eq!(read_command(0x3FFF), 0xFFFF);
        assert_eq!(read_command(0x0000), 0xC000);
        assert_eq!(read_command(0x0001), 0x4001);
        // 0x4000 | 0x3FFC = 0x7FFC has 13 ones: parity bit set.
        assert_eq!(read_command(0x3FFC), 0xFFFC);
    }

    #[test]
    fn reads_the_angle() {
        let mut ex = frame(0xFFFF, response(false, 0));
        ex.extend(frame(0xC000, response(false, 12345)));
        let mut spi = Mock::new(&ex);
        let mut enc = As5047p::new(spi.clone());
        assert_eq!(enc.read_angle_counts(), Ok(12345));
        spi.done();
    }

    #[test]
    fn parity_error_is_reported() {
        let bad = response(false, 12345) ^ 0x0001; // one flipped data bit
        let mut ex = frame(0xFFFF, response(false, 0));
        ex.extend(frame(0xC000, bad));
        let mut spi = Mock::new(&ex);
        let mut enc = As5047p::new(spi.clone());
        assert_eq!(enc.read_angle_counts(), Err(Error::Parity { frame: bad }));
        spi.done();
    }

    #[test]
    fn error_flag_reads_errfl() {
        let mut ex = frame(0xFFFF, response(false, 0));
        ex.extend(frame(0xC000, response(true, 0x1234)));
        ex.extend(frame(0x4001, response(true, 0)));
        ex.extend(frame(0xC000, response(false, 0b100)));
        let mut spi = Mock::new(&ex);
        let mut enc = As5047p::new(spi.clone());
        let e = enc.read_angle_counts();
        assert_eq!(e, Err(Error::ErrorFlag(ErrorFlags(0b100))));
        if let Err(Error::ErrorFlag(f)) = e {
            assert!(f.parity() && !f.framing() && !f.invalid_command());
        }
        spi.done();
    }

    /// A bus that always fails (embedded-hal-mock's SPI mock cannot inject errors).
    struct FailingSpi;
    impl embedded_hal::spi::ErrorType for FailingSpi {
        type Error = embedded_hal::spi::ErrorKind;
    }
    impl SpiDevice for FailingSpi {
        fn transaction(
            &mut self,
            _ops: &mut [embedded_hal::spi::Operation<'_, u8>],
        ) -> Result<(), Self::Error> {
            Err(embedded_hal::spi::ErrorKind::Overrun)
        }
    }

    #[test]
    fn bus_error_is_passed_through() {
        let mut enc = As5047p::new(FailingSpi);
        assert_eq!(
            enc.read_angle_counts(),
            Err(Error::Spi(embedded_hal::spi::ErrorKind::Overrun))
        );
    }

    #[test]
    fn unwraps_across_the_wrap() {
        // Zero at 16380 (4 counts below the wrap); walk up through the wrap and back.
        let mut t = AngleTracker::new(16380, 100);
        let seq: [(u16, i32); 6] = [
            (16380, 0),
            (16383, 3),
            (2, 6),
            (50, 54),
            (16370, -10),
            (16383, 3),
        ];
        for (raw, expect_counts) in seq {
            let a = t.update(raw).unwrap();
            let expect = expect_counts as f32 * 2.0 * PI / 16384.0;
            assert!((a - expect).abs() < 1e-6, "raw {raw}: {a} vs {expect}");
        }
        // Several full turns keep accumulating (no silent wrap back to 0).
        let mut t = AngleTracker::new(0, 8000);
        let mut raw = 0u16;
        for _ in 0..40 {
            raw = (raw + 4096) % 16384;
            t.update(raw).unwrap();
        }
        assert!((t.angle_rad() - 10.0 * 2.0 * PI).abs() < 1e-4);
    }

    #[test]
    fn implausible_jump_is_rejected_and_state_kept() {
        let mut t = AngleTracker::new(0, 100);
        t.update(10).unwrap();
        assert_eq!(t.update(300), Err(TrackError::Jump { step_counts: 290 }));
        // Still relative to 10: a step of 50 from there is accepted.
        let a = t.update(60).unwrap();
        assert!((a - 60.0 * RAD_PER_COUNT).abs() < 1e-6);
    }

    #[test]
    fn calibrate_zero_here() {
        let mut t = AngleTracker::new(0, 100);
        t.update(5000).unwrap();
        t.calibrate_zero_here();
        assert_eq!(t.angle_rad(), 0.0);
        let a = t.update(4990).unwrap();
        assert!((a + 10.0 * RAD_PER_COUNT).abs() < 1e-6);
    }
}

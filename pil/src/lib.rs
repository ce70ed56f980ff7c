//! Processor-in-the-loop (PIL) frames: the firmware image under QEMU closes the loop with the
//! host's plant in lockstep (`shimmy-sim pil`, docs/testing.md, "Processor in the loop").
//!
//! Each 1 kHz control step the host sends one [`HostFrame::Sensors`] (the raw sensor frame of the
//! simulator's sensor models, faults applied) and the firmware answers, on one pipe and in this
//! order, with the [`TargetFrame`]s of that period: the [`StepReport`] of its control task, then
//! what its lower-priority tasks produced before the next step (the meter task's
//! [`MarginFrame`]s and [`TargetFrame::MeterRun`], the background loop's [`ModelFrame`]s).
//! The host sends the next sensor frame only after the step report, so a step never waits on
//! the meter or the model loop. Before the first step the image sends [`TargetFrame::Hello`]
//! (the vehicle model it is built for). [`HostFrame::Finish`] ends the run; the image answers with
//! [`TargetFrame::Finished`] (the instructions it executed) and exits.
//!
//! Encoding: a 2-byte little-endian body length, then the postcard body (floats as their IEEE
//! bits, so a NaN payload and the sign of a zero survive and the host can compare bit for bit).

#![cfg_attr(not(feature = "host"), no_std)]

#[cfg(feature = "host")]
pub mod defmt_log;

use serde::{Deserialize, Serialize};
use shimmy_core::estimator::fusion::MarginReport;
use shimmy_core::estimator::model_margin::ModelMargin;
use shimmy_core::estimator::monitor::Level;
use shimmy_core::supervisor::frame::RawFrame;
use shimmy_core::supervisor::safe_controller::SafeOutput;

/// Bytes of the length header in front of each body.
pub const HEADER_BYTES: usize = 2;
/// Largest frame, header included (a [`StepReport`] is about 110 bytes).
pub const MAX_FRAME: usize = 256;

/// Host -> firmware, once per control step.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum HostFrame {
    /// The raw sensor frame of the step (time stamp from the host's clock).
    Sensors(RawFrame),
    /// The run is over: the image logs its counters and exits through semihosting.
    Finish,
}

/// The control task's report at the end of each step.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct StepReport {
    /// Control step number (the firmware's count).
    pub step: u32,
    /// The supervised step's output: coil command, verdict, validated inputs, controller output.
    pub out: SafeOutput,
    /// Instructions of the control task in this step, entry to exit (QEMU `-icount shift=0`).
    pub instructions: u32,
}

/// One 100 Hz update of the meter task.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct MarginFrame {
    /// Step number of the meter sample that completed the update.
    pub step: u32,
    /// The fused margin report.
    pub report: MarginReport,
    /// The warning level after the update.
    pub level: Level,
    /// Model cycles published before the meter run took the model margin it fused.
    pub model_cycles: u32,
}

/// A completed cycle of the background model-margin loop.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelFrame {
    /// Cycle number, from 1.
    pub cycle: u32,
    /// The published model margin.
    pub margin: ModelMargin,
    /// Instructions the loop spent on the cycle (preemption by the other tasks excluded).
    pub instructions: u32,
}

/// Firmware -> host.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum TargetFrame {
    /// End of a control step.
    Step(StepReport),
    /// A margin update of the meter task.
    Margin(MarginFrame),
    /// End of a meter run (spawned by control step `step`).
    MeterRun {
        /// The spawning step.
        step: u32,
        /// Instructions of the run.
        instructions: u32,
    },
    /// A completed model cycle.
    Model(ModelFrame),
    /// The image's answer to [`HostFrame::Finish`], its last frame.
    Finished {
        /// Instructions the image executed since reset (the virtual time in ns under `-icount
        /// shift=0`: the PIL build never halts, see `firmware/src/board/pil.rs`).
        instructions: u64,
    },
    /// The image's first frame, sent once its link is open: what it is built for, so the host
    /// closes the loop only on the vehicle model the image runs.
    Hello {
        /// The schema id of the image's vehicle record (`shimmy_core::vehicle::
        /// record_schema_of`: one per vehicle model and field table).
        vehicle_schema: u32,
    },
}

/// Why a frame could not be encoded or decoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameError {
    /// The body does not fit [`MAX_FRAME`].
    TooLong,
    /// A header announces `0` or more than [`MAX_FRAME`] - [`HEADER_BYTES`] bytes.
    BadLength(usize),
    /// The body is not a valid frame of the expected type.
    Malformed,
}

impl core::fmt::Display for FrameError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            FrameError::TooLong => write!(f, "frame longer than {MAX_FRAME} bytes"),
            FrameError::BadLength(n) => write!(
                f,
                "frame header announces {n} bytes (allowed 1..={})",
                MAX_FRAME - HEADER_BYTES
            ),
            FrameError::Malformed => write!(f, "malformed frame body"),
        }
    }
}

/// Encodes `msg` with its header into `buf`; the frame is the returned prefix of `buf`.
pub fn encode<'b, T: Serialize>(
    msg: &T,
    buf: &'b mut [u8; MAX_FRAME],
) -> Result<&'b [u8], FrameError> {
    let (head, body) = buf.split_at_mut(HEADER_BYTES);
    let n = postcard::to_slice(msg, body)
        .map_err(|_| FrameError::TooLong)?
        .len();
    head.copy_from_slice(&(n as u16).to_le_bytes());
    buf.get(..HEADER_BYTES + n).ok_or(FrameError::TooLong)
}

/// The body length a header announces, checked against [`MAX_FRAME`].
pub fn body_len(header: [u8; HEADER_BYTES]) -> Result<usize, FrameError> {
    let n = usize::from(u16::from_le_bytes(header));
    if n == 0 || n > MAX_FRAME - HEADER_BYTES {
        Err(FrameError::BadLength(n))
    } else {
        Ok(n)
    }
}

/// Decodes one body (the bytes after the header); trailing bytes are an error.
pub fn decode<'a, T: Deserialize<'a>>(body: &'a [u8]) -> Result<T, FrameError> {
    match postcard::take_from_bytes(body) {
        Ok((v, [])) => Ok(v),
        _ => Err(FrameError::Malformed),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use shimmy_core::supervisor::frame::EncoderReading;

    fn roundtrip<T: Serialize + for<'a> Deserialize<'a>>(msg: &T) -> T {
        let mut buf = [0u8; MAX_FRAME];
        let frame = encode(msg, &mut buf).expect("fits");
        let n = body_len([frame[0], frame[1]]).expect("length");
        assert_eq!(n + HEADER_BYTES, frame.len());
        decode(&frame[HEADER_BYTES..]).expect("decodes")
    }

    /// Floats travel as their bits: a NaN with a payload and a negative zero come back
    /// unchanged (the PIL/SIL comparison is bit for bit).
    #[test]
    fn sensor_frames_keep_every_bit() {
        let nan = f32::from_bits(0x7fc0_1234);
        let msg = HostFrame::Sensors(RawFrame {
            t_us: u32::MAX,
            left: EncoderReading {
                angle_rad: nan,
                read_ok: true,
                parity_ok: false,
                error_flag: true,
            },
            right: EncoderReading::ok(-0.0),
            speed_mps: 12.5,
            speed_valid: false,
            coil_current_a: None,
            coil_drive_a: Some(f32::from_bits(0x7f80_0001)),
        });
        let HostFrame::Sensors(back) = roundtrip(&msg) else {
            panic!("variant changed");
        };
        assert_eq!(back.left.angle_rad.to_bits(), nan.to_bits());
        assert_eq!(back.right.angle_rad.to_bits(), (-0.0f32).to_bits());
        assert_eq!(back.t_us, u32::MAX);
        assert!(!back.left.parity_ok && back.left.error_flag && !back.speed_valid);
        assert_eq!(back.coil_current_a, None);
    }

    /// The largest frame, a step report with every optional field present, fits.
    #[test]
    fn the_largest_frame_fits() {
        let mut out = SafeOutput {
            control: Some(Default::default()),
            ..SafeOutput::default()
        };
        out.validated.angles_rad = Some((1.0, 2.0));
        out.validated.speed_mps = Some(3.0);
        out.validated.coil_current_a = Some(1.0);
        out.verdict.safe_current_a = Some(2.0);
        out.verdict.test_current_a = Some(0.4);
        let msg = TargetFrame::Step(StepReport {
            step: u32::MAX,
            out,
            instructions: u32::MAX,
        });
        let mut buf = [0u8; MAX_FRAME];
        let len = encode(&msg, &mut buf).expect("fits").len();
        assert!(len <= MAX_FRAME, "{len}");
        assert_eq!(roundtrip(&msg), msg);
    }

    #[test]
    fn bad_headers_and_bodies_are_errors() {
        assert_eq!(body_len([0, 0]), Err(FrameError::BadLength(0)));
        assert_eq!(body_len([0xff, 0xff]), Err(FrameError::BadLength(65535)));
        assert_eq!(decode::<TargetFrame>(&[0x7f]), Err(FrameError::Malformed));
        let mut buf = [0u8; MAX_FRAME];
        let frame = encode(
            &HostFrame::Sensors(RawFrame::ok(1, 0.0, 0.0, 1.0)),
            &mut buf,
        )
        .expect("fits")
        .to_vec();
        // A trailing byte is not silently ignored.
        let mut long = frame[HEADER_BYTES..].to_vec();
        long.push(0);
        assert_eq!(decode::<HostFrame>(&long), Err(FrameError::Malformed));
    }
}

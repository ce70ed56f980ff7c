//! The scripted drive of the store check, run by a host test and by the QEMU binary
//! `store-check`: the firmware's own chain (the core `SafeController` at 1 kHz, the core
//! `DataPipeline` through [`DataMargin`], the link's `Recorder`, [`StoreTask`]) on a scripted
//! road, so the log gets what the running firmware would write.
//!
//! | time | road | what the store must get |
//! |---|---|---|
//! | 0-4 s | 20 m/s, both wheels shimmy at [`SHIMMY_HZ`], [`SHIMMY_RAD`] | (the monitor raises `ShimmyPresent`) |
//! | 4-9 s | 20 m/s, calm | the episode closes (~6.9 s, when the yaw envelope has fallen below the release threshold): one shimmy entry, written while moving |
//! | 6-7 s | the coil current reads five times the command, up to full scale (a short) | the supervisor latches `coil-short` (logged at 6.87 s): one fault entry |
//! | 9-14 s | braking to 0 (4 m/s^2) | the margin report becomes unavailable as the braking starts: one fault entry (not latched) |
//! | 14-[`DRIVE_S`] s | standing, coil off | the standstill token: whatever waited for an erase is written |
//!
//! The yaw carries a small road vibration throughout (a still encoder reads as stuck).

use super::flash::FlashError;
use super::task::{Motion, StoreTask};
use crate::link::Batch;
use crate::monitoring::{safe_controller, DataMargin, MeterSample, DT_S};
use embedded_storage_async::nor_flash::NorFlash;
use shimmy_core::supervisor::frame::{RawFrame, NOMINAL_PERIOD_US};
use shimmy_link::log::Recorder;

/// Shimmy frequency of the episode, Hz.
pub const SHIMMY_HZ: f32 = 8.0;
/// Shimmy amplitude of the episode, rad.
pub const SHIMMY_RAD: f32 = 0.02;
/// Cruise speed, m/s.
pub const CRUISE_MPS: f32 = 20.0;
/// Length of the drive, s.
pub const DRIVE_S: f32 = 18.0;
const SHIMMY_END_S: f32 = 4.0;
const SHORT_S: (f32, f32) = (6.0, 7.0);
const BRAKE_S: f32 = 9.0;
const BRAKE_MPS2: f32 = 4.0;

/// What the drive did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DriveSummary {
    /// Entries appended by the store task.
    pub appended: u32,
    /// Entries written by standstill maintenance.
    pub written_at_standstill: u32,
    /// Standstill maintenances that failed.
    pub maintenance_errors: u32,
    /// The coil command at the end, A.
    pub final_cmd_a: f32,
}

fn speed_at(t: f32) -> f32 {
    if t < BRAKE_S {
        CRUISE_MPS
    } else {
        (CRUISE_MPS - BRAKE_MPS2 * (t - BRAKE_S)).max(0.0)
    }
}

fn yaw_at(t: f32) -> f32 {
    let tau = core::f32::consts::TAU;
    let vibration = 2e-4 * libm::sinf(tau * 13.0 * t);
    let shimmy = if t < SHIMMY_END_S {
        SHIMMY_RAD * libm::sinf(tau * SHIMMY_HZ * t)
    } else {
        0.0
    };
    shimmy + vibration
}

/// Runs the drive into `task`.
pub fn run<F: NorFlash<Error = FlashError>>(task: &mut StoreTask<F>) -> DriveSummary {
    let mut ctrl = safe_controller();
    let Ok(mut data) = DataMargin::new() else {
        return DriveSummary::default();
    };
    let mut recorder = Recorder::new();
    let mut summary = DriveSummary::default();
    let mut cmd_peak_a = 0.0f32;
    let mut last_cmd_a = 0.0f32;
    let steps = (DRIVE_S / DT_S) as u32;
    for k in 0..steps {
        let t = k as f32 * DT_S;
        let psi = yaw_at(t);
        let mut frame = RawFrame::ok(k.wrapping_mul(NOMINAL_PERIOD_US), psi, psi, speed_at(t));
        let short = (SHORT_S.0..SHORT_S.1).contains(&t);
        // A healthy coil follows its command; through a short the drive pushes five times the
        // current, up to the channel's 2.5 A full scale.
        frame.coil_current_a = Some(if short {
            (5.0 * last_cmd_a).min(2.5)
        } else {
            last_cmd_a
        });
        let out = ctrl.step(&frame, data.margin_status());
        last_cmd_a = out.current_cmd_a;
        cmd_peak_a = cmd_peak_a.max(out.current_cmd_a);
        recorder.on_command(out.current_cmd_a);
        let Some((u, _)) = data.push(&MeterSample::of(k, &out), None) else {
            continue;
        };
        let mut batch = Batch::new();
        recorder.on_update(data.pipeline().monitor(), &mut batch);
        let sup = ctrl.supervisor();
        recorder.on_faults(k, sup.faults().bits(), sup.latched().bits(), &mut batch);
        let motion = Motion {
            t_s: u.report.t_s,
            speed_mps: data.speed_mps(),
            cmd_peak_a,
        };
        cmd_peak_a = 0.0;
        let pass = task.step(motion, batch.into_iter());
        summary.appended += pass.appended;
        match pass.maintained {
            Some(Ok(m)) => summary.written_at_standstill += m.written,
            Some(Err(_)) => summary.maintenance_errors += 1,
            None => {}
        }
    }
    summary.final_cmd_a = last_cmd_a;
    summary
}

//! Fault memory across resets under QEMU: the reset record in `.uninit` RAM survives a system
//! reset, the latched coil short it carries is restored before the first control step (0 A,
//! FailSafe, never the fail-safe 2 A), and the third quick abnormal reset holds the safe state.
//!
//! Boot 1 finds no valid record (QEMU starts with zeroed RAM: the power-on case), latches a
//! coil short as the supervisor would, and resets (SYSRESETREQ, as the panic handler does).
//! Boots 2 and 3 check the restored latch and reset again; boot 4 must report the reset loop.
//! QEMU has no RCC reset flags, so the cause of the resets this binary makes is given as
//! `Software` (what RCC_CSR says after the panic handler's reset on the board).
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
mod app {
    use cortex_m_rt::entry;
    use shimmy_core::supervisor::faults::{FaultKind, FaultSet};
    use shimmy_core::supervisor::frame::{MarginStatus, RawFrame};
    use shimmy_core::supervisor::policy::Mode;
    use shimmy_firmware::fault_memory::{persist, BootPolicy, ResetCause, ResetRecord};
    use shimmy_firmware::monitoring::safe_controller;
    use shimmy_firmware::runtime::{finish, Outcome};

    fn check(ok: bool, what: &str) {
        if !ok {
            defmt::error!("reset memory check failed: {=str}", what);
            finish(Outcome::Failure);
        }
    }

    #[entry]
    fn main() -> ! {
        let stored = persist::load();
        let cause = if stored.is_valid() {
            ResetCause::Software
        } else {
            ResetCause::PowerOn
        };
        let (mut record, policy) = ResetRecord::on_boot(&stored, cause);
        persist::store(&record);
        let boot = record.resets + 1;
        let mut short = FaultSet::EMPTY;
        short.insert(FaultKind::CoilShort);
        if boot == 1 {
            check(!stored.is_valid(), "boot 1 finds no record");
            record.update(5_000, short.bits());
            persist::store(&record);
            defmt::info!("boot 1: no record (power-on); coil-short latched, software reset");
            cortex_m::peripheral::SCB::sys_reset();
        }
        check(
            record.latched_faults == short.bits(),
            "the latched fault survived",
        );
        if boot < 4 {
            check(
                policy == BootPolicy::Run,
                "run normally below the loop count",
            );
            // What init does: restore before the first step.
            let mut ctrl = safe_controller();
            ctrl.supervisor_mut()
                .restore_latched(FaultSet::from_bits(record.latched_faults));
            let mut f = RawFrame::ok(0, 0.0, 0.0, 20.0);
            f.coil_current_a = Some(0.0);
            let o = ctrl.step(&f, MarginStatus::NotUsed);
            check(
                o.verdict.mode == Mode::FailSafe && o.current_cmd_a == 0.0,
                "a restored coil short gets 0 A",
            );
            defmt::info!(
                "boot {=u32}: record valid, {=u32} resets, coil-short restored: FailSafe at 0 A; reset",
                boot,
                record.resets
            );
            record.update(5_000, ctrl.supervisor().latched().bits());
            persist::store(&record);
            cortex_m::peripheral::SCB::sys_reset();
        }
        check(
            policy == BootPolicy::HoldSafe,
            "the 3rd quick reset holds the safe state",
        );
        defmt::info!(
            "boot 4: {=u8} abnormal resets in a row within 60 s: reset loop, holding the safe state; reset memory ok",
            record.quick_resets
        );
        finish(Outcome::Success)
    }
}

#[cfg(not(target_os = "none"))]
fn main() {}

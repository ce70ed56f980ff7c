//! Host/target conformance, target side: replays the committed sensor trace
//! (`tests/fixtures/conformance-trace.bin`, recorded from the host simulator) through
//! [`shimmy_firmware::replay::replay`] on the Cortex-M4F (under QEMU) and prints each output
//! channel's digest. `cargo xtask test` compares them with the host's digests (written by
//! `tests/tests/cross_crate/conformance.rs`) and fails on any difference.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
mod run {
    use shimmy_core::vehicles::car::PlantParams;
    use shimmy_firmware::replay::{replay, CHANNELS};
    use shimmy_firmware::runtime::{finish, Outcome};

    static TRACE: &[u8] = include_bytes!("../../../tests/fixtures/conformance-trace.bin");

    #[cortex_m_rt::entry]
    fn main() -> ! {
        shimmy_firmware::stack::paint();
        let d = match replay(TRACE, &PlantParams::nominal()) {
            Ok(d) => d,
            Err(e) => {
                defmt::error!("replay failed: {}", defmt::Debug2Format(&e));
                finish(Outcome::Failure)
            }
        };
        defmt::info!(
            "conformance samples {=u32}, supervisor: fail-safe {=u32}, degraded {=u32}, mode changes {=u32}; worst level {=u8}",
            d.samples,
            d.failsafe,
            d.degraded,
            d.mode_changes,
            d.worst_level as u8
        );
        for (name, c) in CHANNELS.iter().zip(d.channels.iter()) {
            defmt::info!(
                "conformance | {=str} | {=u32} | {=u64:016x} | {=u64:016x}",
                name,
                c.count,
                c.hash.0,
                c.last_bits
            );
        }
        let (used, size) = shimmy_firmware::stack::high_water();
        defmt::info!(
            "stack high-water mark (replay) {=usize} B of {=usize} B",
            used,
            size
        );
        finish(Outcome::Success)
    }
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("conformance runs on the Cortex-M4F: use `cargo xtask test` (QEMU).");
    std::process::exit(2);
}

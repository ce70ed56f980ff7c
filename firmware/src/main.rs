//! The firmware application. On the host this binary only explains how to build it.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
mod app {
    use shimmy_core::params::ParamSet;
    use shimmy_firmware::runtime::{finish, Outcome};

    #[cortex_m_rt::entry]
    fn main() -> ! {
        defmt::info!(
            "{=str} booted (core {=str})",
            shimmy_firmware::BANNER,
            shimmy_core::VERSION
        );
        let p = ParamSet::Nominal.params();
        defmt::info!(
            "model: nominal set, K_d = {=f64} N m/rad, C_a = {=f64} N/rad",
            p.k_d,
            p.c_a
        );
        // TODO(issue 6): start the 1 kHz control task and the estimator task.
        finish(Outcome::Success)
    }
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!(
        "shimmy-firmware runs on a Cortex-M4F: build it with --target thumbv7em-none-eabihf, \
         run it under QEMU with `cargo xtask qemu`, or flash a board (see README)."
    );
    std::process::exit(2);
}

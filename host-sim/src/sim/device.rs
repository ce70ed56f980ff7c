//! The host link to a device (a board, QEMU or the in-process simulated device) and the
//! processor-in-the-loop run against the firmware's host-compilable application.

pub mod device_link;
pub mod pil;
pub mod sim_device;

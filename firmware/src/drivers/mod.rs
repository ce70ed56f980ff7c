//! Sensor and actuator drivers, generic over embedded-hal 1.0 traits (or small traits owned by
//! the firmware where embedded-hal has none) and tested on the host with embedded-hal-mock.

pub mod as5047p;
pub mod coil_current;
pub mod coil_pwm;
pub mod wheel_speed;

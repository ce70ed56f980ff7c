//! Hopf crossings.

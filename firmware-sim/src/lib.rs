//! The spike camera, simulated.

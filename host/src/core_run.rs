//! Owned buffers for the core, shared with the firmware loop.
pub use spiv_firmware_sim::buffers::{HistoryBuf, WorkspaceBuf};

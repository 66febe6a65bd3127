//! The cameras in front of the scene: the integrate-and-fire spike sensor
//! ([`spike`]) and the frame camera it is compared with ([`frame`]).

pub mod frame;
pub mod spike;

pub use frame::{FrameCamera, FrameCameraParams};
pub use spike::{simulate, Reset, SensorParams, SpikeSensor};

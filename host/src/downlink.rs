//! The host's end of the downlink: after each received pair, a control
//! message back to the sidecar (`spiv_core::wire::control`) with the motion
//! that pair's PIV measured, as a velocity per stored row, for the sidecar's
//! motion-compensated frames from the next pair on — and, optionally, the
//! dwell caps of its adaptive frames. Time-resolved: the field of pair `p`
//! predicts pair `p + 1`, and the sidecar refines it from its own spikes.
//!
//! A field with fewer than half its vectors measured predicts nothing: the
//! control then carries no motion and the sidecar goes back to the paper's
//! adaptive frames until a usable field comes.

use std::io::Write;

use spiv_core::wire::control::Control;
use spiv_core::Params;
use spiv_formats::vectors::Vector;

use crate::predict::{motion_grid, predicts, MotionModel, Prediction};
use crate::receive::ReceivedFrame;
use crate::Error;

/// What the host sent.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct DownlinkReport {
    /// Controls written.
    pub sent: u64,
    /// Of those, carrying a motion.
    pub with_motion: u64,
    /// Of those, a motion on a grid of more than one tile column
    /// ([`crate::predict::motion_grid`]).
    pub with_grid: u64,
    /// Controls the link refused to take (the sidecar gone, no OUT
    /// endpoint); not retried.
    pub failed: u64,
}

/// The control for the pair after `pair`, from its PIV `field` (upright,
/// px per pair): row or tile-column velocities
/// ([`crate::predict::motion_grid`]) when at least half the field was measured,
/// caps per band when `dwell_budget` (px of blur) is given; `model`
/// bounds the motion's model.
pub fn control_for(
    pair: &[ReceivedFrame; 2],
    field: &[Vector],
    dwell_budget: Option<f64>,
    core: &Params,
    model: MotionModel,
) -> Control {
    let a = &pair[0];
    let dt = f64::from(a.end.dt.max(1));
    let motion = if !field.is_empty() && predicts(field) {
        motion_grid(field, (a.width, a.height), true, dt, model)
    } else {
        Prediction::rows((Vec::new(), Vec::new()))
    };
    let caps = match dwell_budget {
        Some(b) => crate::dwell::band_caps(field, usize::from(a.height), dt, b, core),
        None => Vec::new(),
    };
    Control {
        caps,
        ..motion.control()
    }
}

/// Writes controls to the sidecar.
pub struct Downlink {
    out: Box<dyn Write + Send>,
    seq: u32,
    /// What was sent.
    pub report: DownlinkReport,
}

impl std::fmt::Debug for Downlink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Downlink")
            .field("seq", &self.seq)
            .field("report", &self.report)
            .finish()
    }
}

impl Downlink {
    /// Controls into `out` (a TCP stream, a USB OUT endpoint, a file or
    /// FIFO).
    pub fn new(out: Box<dyn Write + Send>) -> Self {
        Downlink {
            out,
            seq: 0,
            report: DownlinkReport::default(),
        }
    }

    /// Sends `control` for the pairs after `pair` (a frame of it gives the
    /// sensor size). A link that refuses is counted, not fatal: the
    /// sidecar runs on without the prediction.
    pub fn send(&mut self, pair: &[ReceivedFrame; 2], control: &Control) -> Result<(), Error> {
        let a = &pair[0];
        let m = control
            .message(a.end.pair.wrapping_add(1), self.seq, a.width, a.height)
            .map_err(Error::control)?;
        self.seq = self.seq.wrapping_add(1);
        match self.out.write_all(&m).and_then(|()| self.out.flush()) {
            Ok(()) => {
                self.report.sent += 1;
                if !control.motion.0.is_empty() {
                    self.report.with_motion += 1;
                    if control.cols > 1 {
                        self.report.with_grid += 1;
                    }
                }
            }
            Err(_) => self.report.failed += 1,
        }
        Ok(())
    }

    /// Sends an ask of the live loop of the time ladder (its messages,
    /// [`crate::estimator::control::Ask::messages`]); `with_motion` when it
    /// carries a flow. A link that refuses is counted, not fatal.
    pub fn send_ask(&mut self, messages: &[Vec<u8>], with_motion: bool) {
        let mut write = || -> std::io::Result<()> {
            for m in messages {
                self.out.write_all(m)?;
            }
            self.out.flush()
        };
        match write() {
            Ok(()) => {
                self.report.sent += 1;
                self.report.with_motion += u64::from(with_motion);
            }
            Err(_) => self.report.failed += 1,
        }
    }
}

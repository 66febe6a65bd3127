//! What every strip of one frame shares: the history and the span of
//! planes of the longest window, the frame's tick, the parameters, the
//! particle test's tables, and the segmentation windows. Built once per
//! frame by [`crate::frame`], read by the segmentation and the adaptive
//! windows (so neither depends on the frame module that calls them), and
//! the predicted motion when the frame is motion-compensated.

use crate::history::History;
use crate::motion::Motion;
use crate::params::{Params, MAX_LEVELS};
use crate::particle::Thresholds;
use crate::window::{Offsets, Span};

/// What every strip of one frame shares.
pub(crate) struct Ctx<'a, 'h> {
    pub hist: &'a History<'h>,
    pub span: &'a Span<'a>,
    /// Each centred window's planes in `span`.
    pub wins: &'a Offsets,
    pub k: u32,
    pub p: &'a Params,
    pub th: &'a Thresholds,
    pub levels: &'a [u16; MAX_LEVELS],
    pub lens: &'a [u16; MAX_LEVELS],
    pub fs: u16,
    /// The predicted motion of each band row: particles are segmented and
    /// integrated on counts compensated for it (`None`: plain counts).
    pub motion: Option<Motion<'a>>,
}

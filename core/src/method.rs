//! How a frame is made: from the spike history at a tick, by the paper's
//! adaptive integration, its two baselines (TFP, TFI) or adaptive
//! integration on motion-compensated counts; or, in the live loop of the
//! time ladder, as a rung frame of events warped along the host's flow.
//! The code is what a frame end carries on the wire
//! ([`crate::wire::FrameEnd::method`]).

/// How a frame is made.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Method {
    /// The paper's adaptive integration: segmentation, background
    /// suppression and an SNR-optimal window per particle region, up to
    /// `Params::n_max` ticks ([`crate::reconstruct_adaptive`]).
    Adaptive = 0,
    /// Spike count over a fixed window: gray = FS·c/n
    /// ([`crate::window::tfp`]).
    Tfp = 1,
    /// Inverse inter-spike interval around the tick
    /// ([`crate::window::tfi`]).
    Tfi = 2,
    /// Adaptive integration on motion-compensated counts (beyond the
    /// paper): each particle counted along its predicted path
    /// ([`crate::reconstruct_compensated`]); needs a predicted motion.
    Mc = 3,
    /// The time ladder's frames: the events of a span of ticks less each
    /// pixel's static light, warped along the host's node flow to the
    /// frame's centre ([`crate::rungs::rung_frames`]), and the events
    /// themselves. Made by the live loop's pairs ([`crate::rungs`]), not
    /// one frame at a tick.
    Ladder = 4,
}

impl Method {
    /// All five, in wire-code order.
    pub const ALL: [Method; 5] = [
        Method::Adaptive,
        Method::Tfp,
        Method::Tfi,
        Method::Mc,
        Method::Ladder,
    ];

    /// The wire code (0–4).
    pub const fn code(self) -> u8 {
        self as u8
    }

    /// The method of a wire code, `None` for an unknown one.
    pub const fn from_code(code: u8) -> Option<Method> {
        match code {
            0 => Some(Method::Adaptive),
            1 => Some(Method::Tfp),
            2 => Some(Method::Tfi),
            3 => Some(Method::Mc),
            4 => Some(Method::Ladder),
            _ => None,
        }
    }

    /// Its lower-case name (`adaptive`, `tfp`, `tfi`, `mc`, `ladder`), as the CLI and the
    /// reports spell it.
    pub const fn name(self) -> &'static str {
        match self {
            Method::Adaptive => "adaptive",
            Method::Tfp => "tfp",
            Method::Tfi => "tfi",
            Method::Mc => "mc",
            Method::Ladder => "ladder",
        }
    }

    /// The method named `name` (see [`Method::name`]).
    ///
    /// ```
    /// use spiv_core::Method;
    /// assert_eq!(Method::from_name("tfp"), Some(Method::Tfp));
    /// assert_eq!(Method::from_name("TFP"), None);
    /// ```
    pub fn from_name(name: &str) -> Option<Method> {
        Method::ALL.into_iter().find(|m| m.name() == name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_and_names_round_trip() {
        for m in Method::ALL {
            assert_eq!(Method::from_code(m.code()), Some(m));
            assert_eq!(Method::from_name(m.name()), Some(m));
        }
        assert_eq!(Method::from_code(5), None);
        assert_eq!(Method::from_name("TFP"), None);
        assert_eq!([0, 1, 2, 3, 4], Method::ALL.map(Method::code));
    }
}

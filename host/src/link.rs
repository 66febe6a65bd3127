//! The sidecar link in process: the firmware loop over a recorded spike
//! stream, its messages through the host's decoder and reassembly, and PIV on
//! the pairs that arrive — so `spiv run` and the link benchmark exercise the
//! same bytes a real sidecar would send.

use spiv_core::wire::Encoding;
use spiv_core::Method;
use spiv_firmware_sim::firmware::{run_on_planes, Config, Control, SentFrame};
use spiv_formats::vectors::Vector;

use crate::piv::{piv, Settings};
use crate::receive::{receive, upright_f32, Event, FrameLimit, ReceivedFrame, Report, Source};
use crate::Error;

/// Bytes in memory as a [`Source`].
#[derive(Debug)]
pub struct Memory(std::io::Cursor<Vec<u8>>);

impl Memory {
    /// A source over `bytes`.
    pub fn new(bytes: Vec<u8>) -> Self {
        Memory(std::io::Cursor::new(bytes))
    }
}

impl Source for Memory {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Error> {
        use std::io::Read;
        self.0.read(buf).map_err(|source| Error::Io {
            what: "memory".into(),
            source,
        })
    }
    fn name(&self) -> String {
        "memory".into()
    }
}

/// What went over the link.
#[derive(Debug, Clone)]
pub struct Transfer {
    /// Pairs as received (stored row order).
    pub pairs: Vec<[ReceivedFrame; 2]>,
    /// Frames as the firmware made them (to compare).
    pub sent: Vec<SentFrame>,
    /// Receiver counts.
    pub report: Report,
    /// Bytes on the wire.
    pub bytes: u64,
    /// Tiles per encoding used: raw8, raw16, lossless coded, lossy.
    pub tiles: [u32; 4],
}

/// Runs the firmware with `cfg` and window `caps` per band (empty: none)
/// over `planes` and receives its messages.
pub fn transfer(
    planes: &[u8],
    width: u16,
    height: u16,
    cfg: Config,
    caps: Vec<u16>,
) -> Result<Transfer, Error> {
    let control = Control {
        caps,
        ..Control::default()
    };
    transfer_with(planes, width, height, cfg, control)
}

/// [`transfer`] with everything the host tells the sidecar (caps and the
/// predicted motion of `Mc` frames), as the control link will carry it.
pub fn transfer_with(
    planes: &[u8],
    width: u16,
    height: u16,
    cfg: Config,
    control: Control,
) -> Result<Transfer, Error> {
    let mut fw = run_on_planes(planes, width, height, cfg, control, Vec::new(), true)?;
    let counters = fw.counters();
    let sent = fw.keep.take().unwrap_or_default();
    let bytes = fw.into_link();
    let mut pairs = Vec::new();
    let report = receive::<Error>(
        &mut Memory::new(bytes),
        FrameLimit::default(),
        |e| {
            if let Event::Pair(p) = e {
                pairs.push(*p);
            }
            Ok(())
        },
        |_| {},
    )?;
    Ok(Transfer {
        pairs,
        sent,
        report,
        bytes: counters.bytes,
        tiles: counters.tiles,
    })
}

/// PIV on every pair.
pub fn piv_pairs(pairs: &[[ReceivedFrame; 2]], s: &Settings) -> Result<Vec<Vec<Vector>>, Error> {
    use rayon::prelude::*;
    pairs
        .par_iter()
        .map(|[a, b]| Ok(piv(&upright_f32(a), &upright_f32(b), None, s)?.vectors()))
        .collect()
}

/// The control of motion-compensated pairs, predicted as `spiv run` and
/// `spiv bench link` do it: the row velocities of `field` (PIV of a TFP
/// pair, measured over `dt` ticks), then [`crate::predict::ROUNDS`] − 1
/// more rounds, each from the PIV (`mc_piv`) of the first compensated pair
/// the previous control made through the link with `cfg` (its method is
/// set to [`Method::Mc`]; refine as `cfg` says). Returns the last control
/// and the transfer it made, or `None` when `field` cannot predict
/// ([`crate::predict::predicts`]). A round whose field cannot predict ends
/// the rounds.
pub fn mc_transfer(
    planes: &[u8],
    (width, height): (u16, u16),
    cfg: Config,
    field: &[Vector],
    dt: f64,
    mc_piv: &Settings,
) -> Result<Option<(Control, Transfer)>, Error> {
    use crate::predict::{motion_grid, predicts, MotionModel, ROUNDS};
    if !predicts(field) {
        return Ok(None);
    }
    let cfg = Config {
        method: Method::Mc,
        ..cfg
    };
    let model = MotionModel::Auto;
    let mut control = motion_grid(field, (width, height), true, dt, model).control();
    let mut t = transfer_with(planes, width, height, cfg, control.clone())?;
    for _ in 1..ROUNDS {
        let Some([a, b]) = t.pairs.first() else {
            break;
        };
        let f = piv(&upright_f32(a), &upright_f32(b), None, mc_piv)?.vectors();
        if !predicts(&f) {
            break;
        }
        control = motion_grid(&f, (width, height), true, dt, model).control();
        t = transfer_with(planes, width, height, cfg, control.clone())?;
    }
    Ok(Some((control, t)))
}

/// Beyond the paper (docs/spec.md §5): adaptive window limits per band of 32 upright
/// rows from the TFP pair's PIV, so the fastest particle near a band blurs
/// by at most `budget` px. The TFP pair goes through the link like any
/// other (a sidecar sends it on request); the limits would go back down
/// the control endpoint. Empty when no TFP pair arrived.
pub fn dwell_caps(
    planes: &[u8],
    width: u16,
    height: u16,
    base: &Config,
    tfp_window: u16,
    budget: f64,
    s: &Settings,
) -> Result<(Vec<u16>, Transfer), Error> {
    let (field, t) = tfp_field(planes, width, height, base, tfp_window, s)?;
    if field.is_empty() {
        return Ok((Vec::new(), t));
    }
    let caps = crate::dwell::band_caps(
        &field,
        usize::from(height),
        f64::from(base.schedule.dt),
        budget,
        &base.params,
    );
    Ok((caps, t))
}

/// The first TFP pair (window `tfp_window`, lossless) through the link and
/// its PIV with `s` (upright, px per pair; empty when no pair arrived):
/// what the host predicts dwell caps and motion from.
pub fn tfp_field(
    planes: &[u8],
    width: u16,
    height: u16,
    base: &Config,
    tfp_window: u16,
    s: &Settings,
) -> Result<(Vec<Vector>, Transfer), Error> {
    let mut cfg = Config {
        method: Method::Tfp,
        tfp_window,
        encoding: Encoding::Rice,
        ..*base
    };
    cfg.schedule.pairs = Some(1);
    let t = transfer(planes, width, height, cfg, Vec::new())?;
    let Some([a, b]) = t.pairs.first() else {
        return Ok((Vec::new(), t));
    };
    let field = piv(&upright_f32(a), &upright_f32(b), None, s)?.vectors();
    Ok((field, t))
}

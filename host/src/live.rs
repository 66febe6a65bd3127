//! The live closed loop: frames from a sidecar, PIV on every pair, and the
//! measured motion sent back so that the sidecar compensates its next
//! frames along it (sensor → core → wire → host → PIV → control →
//! sidecar). `spiv receive` and the Python package run it.

use std::path::{Path, PathBuf};

use std::collections::VecDeque;

use spiv_core::pairs::CorePair;
use spiv_core::wire::pair::PairHead;
use spiv_formats::image::write_levels;
use spiv_formats::vectors::{write_vectors, write_vectors_uncertain};

use crate::downlink::{control_for, Downlink, DownlinkReport};
use crate::estimator::control::Ask;
use crate::estimator::ladder::{self, LadderSettings, Measurement};
use crate::estimator::make::pair_input;
use crate::piv::{piv, Settings};
use crate::receive::source::Source;
use crate::receive::{receive, Event, FrameLimit, ReceivedFrame, Report};
use crate::receive::{receiver_settings, upright_f32};
use crate::Error;
use spiv_estimator::units::{PerTick, Ticks};

/// What the loop does with what it receives.
#[derive(Debug, Clone, PartialEq)]
pub struct LiveOptions {
    /// Largest frame accepted (a larger or empty one is corrupt).
    pub max_frame: FrameLimit,
    /// PIV window side of each pass, px, when PIV runs on every pair
    /// (`None`: no PIV). Plain pairs take [`receiver_settings`],
    /// motion-compensated ones [`Settings::for_compensated_frames`] with
    /// these passes.
    pub piv_windows: Option<Vec<usize>>,
    /// Folder for every frame (PNG, upright) and the vectors
    /// (`vectors_NNNNN.csv`).
    pub out: Option<PathBuf>,
    /// The motion model of the controls sent
    /// ([`crate::predict::motion_grid`]).
    pub motion_model: crate::predict::MotionModel,
    /// The time ladder that measures the pairs of a live loop of the
    /// ladder (a sidecar run with `--method ladder`), when PIV runs.
    pub ladder: LadderSettings,
}

/// What the loop received, measured and sent.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct LiveReport {
    /// The receiver's counts.
    pub received: Report,
    /// Vectors measured over all pairs.
    pub vectors: usize,
    /// Control messages sent, when the loop was closed.
    pub downlink: Option<DownlinkReport>,
}

/// Where the closed loop's control messages go: into `path` (a file or a
/// FIFO that `spiv-firmware-sim --control` reads), or back on `source`'s
/// own link (TCP, USB OUT) when `path` is `None`.
pub fn open_downlink(source: &dyn Source, path: Option<&Path>) -> Result<Downlink, Error> {
    match path {
        Some(path) => {
            let f = std::fs::OpenOptions::new()
                .write(true)
                .create(true)
                .truncate(true)
                .open(path)
                .map_err(|e| Error::io(format!("control: {}", path.display()), e))?;
            Ok(Downlink::new(Box::new(f)))
        }
        None => match source.downlink() {
            Some(out) => Ok(Downlink::new(out?)),
            None => Err(Error::Control(format!(
                "{} has no way back to the sidecar; give a path for the control messages",
                source.name()
            ))),
        },
    }
}

/// Receives from `source` until it ends; with `opts.piv_windows`, runs PIV
/// on every pair and, with a `downlink`, sends the sidecar each pair's
/// motion (window caps and the prediction per row or tile column,
/// [`control_for`]).
/// `progress` sees the counts as they grow.
pub fn run_live(
    source: &mut dyn Source,
    opts: &LiveOptions,
    mut downlink: Option<Downlink>,
    progress: impl FnMut(&Report),
) -> Result<LiveReport, Error> {
    let core = spiv_core::Params::default();
    if let Some(d) = &opts.out {
        std::fs::create_dir_all(d).map_err(spiv_formats::io_err(d))?;
    }
    let (plain, compensated) = match &opts.piv_windows {
        Some(w) => {
            let mut mc = Settings::for_compensated_frames();
            mc.windows = w.clone();
            (Some(receiver_settings(w.clone())), Some(mc))
        }
        None => (None, None),
    };
    let mut vectors = 0usize;
    let mut ladder = LadderHost::new(opts.ladder.clone());
    let received = receive::<Error>(
        source,
        opts.max_frame,
        |e| {
            match e {
                Event::Frame(f) => {
                    if let Some(d) = &opts.out {
                        save_frame(d, &f)?;
                    }
                }
                Event::Ladder(p) => {
                    let (head, pair) = &*p;
                    if opts.piv_windows.is_none() {
                        return Ok(());
                    }
                    let (m, ask) = ladder.measure(head, pair)?;
                    let v = m.field.vectors();
                    vectors += v.len();
                    if let Some(d) = downlink.as_mut() {
                        let next = head.pair.wrapping_add(1);
                        let messages = ask.messages(next, pair.size, true)?;
                        ladder.sent(next, &ask);
                        d.send_ask(&messages, ask.warm());
                    }
                    if let Some(d) = &opts.out {
                        let sigma: Vec<(f64, f64)> = m.field.sigma.iter().copied().collect();
                        let path = d.join(format!("vectors_{:05}.csv", head.pair));
                        write_vectors_uncertain(&path, &v, &sigma)?;
                    }
                }
                Event::Pair(pair) => {
                    let [fa, fb] = &*pair;
                    let s = match fa.end.method {
                        spiv_core::Method::Mc => compensated.as_ref(),
                        _ => plain.as_ref(),
                    };
                    if let Some(s) = s {
                        let field = piv(&upright_f32(fa), &upright_f32(fb), None, s)?;
                        let v = field.vectors();
                        vectors += v.len();
                        if let Some(d) = downlink.as_mut() {
                            let c = control_for(&pair, &v, None, &core, opts.motion_model);
                            d.send(&pair, &c)?;
                        }
                        if let Some(d) = &opts.out {
                            write_vectors(&d.join(format!("vectors_{:05}.csv", fa.end.pair)), &v)?;
                        }
                    }
                }
            }
            Ok(())
        },
        progress,
    )?;
    if received.bytes > 0 && received.messages == 0 {
        return Err(Error::NotWire);
    }
    Ok(LiveReport {
        received,
        vectors,
        downlink: downlink.map(|d| d.report),
    })
}

/// Asks in flight whose fields the host keeps, at most: a sidecar that
/// hears none of them follows the oldest, which is then forgotten.
const ASKS_KEPT: usize = 64;

/// The host end of the live loop of the time ladder: each pair measured by
/// `spiv flow`'s ladder ([`ladder::measure`]; the stream's first
/// [`crate::flow::WARMUP`] pairs as `spiv flow` measures its warm-up
/// pairs, without the dense rescue), and the ask for the pairs after it
/// ([`Ask::after`]), with the field each ask was sent from kept until the
/// sidecar's pairs follow a newer one.
#[derive(Debug)]
struct LadderHost {
    cfg: LadderSettings,
    starts: VecDeque<(u32, Option<PerTick>)>,
}

impl LadderHost {
    fn new(cfg: LadderSettings) -> LadderHost {
        LadderHost {
            cfg,
            starts: VecDeque::new(),
        }
    }

    /// Measures `pair` (upright, stored bottom-up as the wire carries
    /// frames): its field in px per the head's `dt` ticks, and the ask for
    /// the pairs after it.
    fn measure(&mut self, head: &PairHead, pair: &CorePair) -> Result<(Measurement, Ask), Error> {
        let start = self.start_for(pair);
        let (w, h) = (usize::from(pair.size.0), usize::from(pair.size.1));
        let input = pair_input(pair, w, true, start.as_ref());
        let dt = f64::from(head.dt.max(1));
        let rescue = head.pair >= crate::flow::WARMUP as u32;
        let m = ladder::measure(
            &input,
            u64::from(head.mid),
            Ticks(dt),
            &self.cfg,
            (w, h),
            rescue,
        )?;
        let ask = Ask::after(&m, &self.cfg);
        Ok((m, ask))
    }

    /// The field the ask `pair`'s rung frames followed was sent from; the
    /// fields of older asks are forgotten. A pair without rung frames
    /// followed no ask (`NO_ASK`): the asks in flight stay for the pairs
    /// after it.
    fn start_for(&mut self, pair: &CorePair) -> Option<PerTick> {
        if pair.rungs.is_empty() {
            return None;
        }
        while self
            .starts
            .front()
            .is_some_and(|(p, _)| *p < pair.from_pair)
        {
            self.starts.pop_front();
        }
        match self.starts.front() {
            Some((p, f)) if *p == pair.from_pair => f.clone(),
            _ => None,
        }
    }

    /// `ask` was sent for the pairs from `from_pair` on.
    fn sent(&mut self, from_pair: u32, ask: &Ask) {
        let start = ask.flow.clone().filter(|_| !ask.rungs.is_empty());
        self.starts.push_back((from_pair, start));
        while self.starts.len() > ASKS_KEPT {
            self.starts.pop_front();
        }
    }
}

/// Writes a received frame as `frame_NNNNN_{a,b}.png`, upright.
fn save_frame(dir: &Path, f: &ReceivedFrame) -> Result<(), Error> {
    let path = dir.join(format!(
        "frame_{:05}_{}.png",
        f.end.pair,
        if f.end.member == 0 { "a" } else { "b" }
    ));
    let up = f.upright();
    let (w, h) = (u32::from(f.width), u32::from(f.height));
    write_levels(&path, w, h, &up, f.end.full_scale)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::piv::{Grid, State};
    use spiv_core::wire::pair::NO_ASK;

    fn pair(from_pair: u32, rungs: usize) -> CorePair {
        CorePair {
            size: (64, 48),
            mid: 100,
            from_pair,
            rungs: (0..rungs)
                .map(|_| (16, [vec![0; 64 * 48], vec![0; 64 * 48]]))
                .collect(),
            events: None,
        }
    }

    fn ask(u: f64) -> Ask {
        let mut f = crate::piv::Field::unmeasured(Grid::new(64, 48, 16, 8).unwrap());
        f.u.fill(u);
        f.state.fill(State::Valid);
        Ask {
            flow: Some(PerTick(f)),
            rungs: vec![16, 32],
            reach: 0,
        }
    }

    /// Pairs made before an ask arrived (cold, late asks) leave it for the
    /// pairs that follow it; a pair names the ask it followed and gets the
    /// field that ask was sent from; older asks are then forgotten.
    #[test]
    fn each_pair_is_measured_from_the_field_its_ask_was_sent_from() {
        let mut host = LadderHost::new(LadderSettings::default());
        host.sent(1, &ask(0.1));
        host.sent(2, &ask(0.2));
        assert!(host.start_for(&pair(NO_ASK, 0)).is_none());
        assert!(host.start_for(&pair(NO_ASK, 0)).is_none());
        let u = |f: Option<PerTick>| f.map(|f| f.u[[0, 0]]);
        assert_eq!(u(host.start_for(&pair(2, 2))), Some(0.2));
        // The ask of pair 1 was overtaken: gone.
        assert_eq!(u(host.start_for(&pair(1, 2))), None);
        assert_eq!(u(host.start_for(&pair(2, 1))), Some(0.2));
    }
}

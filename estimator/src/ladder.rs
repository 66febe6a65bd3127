//! The time ladder: a pair's flow measured from the spikes around it, over
//! separations that grow as the motion becomes known.
//!
//! Rung `s` makes two compensated innovation frames
//! ([`spiv_core::rungs::rung_frames`]) from adjacent, disjoint stretches of the
//! recording — A from the `s` ticks before the pair's midpoint, B from the
//! `s` ticks after — each showing the particles where they are at its own
//! centre, `s` ticks apart, and PIV measures the displacement between them
//! with the field known so far (its paths over `s`) as the predictor.
//! Disjoint frames share no spike, so the measurement does not lean
//! towards the prediction, and centred windows keep a prediction error a
//! blur rather than a bias. The first rungs (4 and 8 ticks: little blur
//! whatever the speed) are uncompensated and measured as one ensemble of
//! the consecutive frames within 32 ticks of the midpoint
//! ([`piv_ensemble`]), so particles too dim or sparse for one pair add
//! up; without a measured motion no rung is longer
//! ([`BOOTSTRAP_LONGEST`]). Each later rung doubles `s`, compensated
//! along the field so far, so the frames gather more light and the same
//! pixel error becomes a smaller velocity error. A vector of an
//! uncompensated rung that the first usable compensated rung cannot
//! confirm is dropped (`unconfirmed`).
//!
//! Every vector of every rung carries its uncertainty from the correlation
//! statistics ([`spiv_piv::correlate::uncertainty`]), scaled to the
//! pair's `dt`; each grid node keeps the rung whose valid vector is the
//! most certain. Where the flow curves or shears too much for a longer
//! rung, its vectors fail validation or come out less certain, and the
//! shorter rung stands. The ladder climbs while rungs fit the recording
//! around the pair and each rung's field is usable; a node no rung measured is replaced from its neighbours or
//! stays invalid.
//!
//! Where the ladder's field is not usable in the end, or flags more than
//! [`ENSEMBLE_FLAGGED`] of its vectors (eddies below the windows,
//! displacements beyond them), the dense ensemble ([`crate::ensemble`])
//! measures the pair instead, if its field is usable. It leaves the mask
//! out as the compensated rungs do; the flow job flags masked nodes.

use ndarray::Array2;

use rayon::prelude::*;

use spiv_piv::{piv_ensemble, piv_predicted, validate, Field, PivError, Settings, State, NO_SIGMA};

use spiv_piv::dense::Flow;
use spiv_piv::Grid;

use crate::compensate::WarpFlow;
use crate::ensemble;
use crate::events::Events;
use crate::joint::JointSettings;
use crate::units::{PerPair, PerTick, Ticks};
use crate::Velocity;

/// Separations of the rungs, ticks, shortest first.
pub const SEPARATIONS: [u32; 6] = [4, 8, 16, 32, 64, 128];

/// Longest rung measured without an estimate of the motion, ticks: an
/// uncompensated window blurs by the whole motion over it, so without a
/// measured motion no window is longer (never the longest window on a
/// guess).
pub const BOOTSTRAP_LONGEST: u32 = 8;

/// Ticks on each side of the midpoint whose uncompensated frames an
/// unestimated rung sums as one ensemble.
pub const BOOTSTRAP_REACH: u32 = 32;

/// PIV windows of the unestimated rungs, px: its frames are short and
/// noisy, and later rungs refine what it finds.
pub const BOOTSTRAP_WINDOWS: [usize; 3] = [64, 32, 32];

/// What the ladder does.
#[derive(Debug, Clone, PartialEq)]
pub struct LadderSettings {
    /// Separations tried, ticks, shortest first (each ≥ 2).
    pub separations: Vec<u32>,
    /// Longest rung tried before any rung measured, ticks.
    pub bootstrap_longest: u32,
    /// Ticks on each side of the midpoint an unestimated rung's ensemble
    /// spans.
    pub bootstrap_reach: u32,
    /// PIV of every rung (the first, without a predictor, also tries the
    /// rescue rungs).
    pub piv: Settings,
    /// Pixels the uncompensated bootstrap rungs leave out of their
    /// correlation (upright, the frames' size; `true`: masked): a wall, a
    /// body, a region outside the flow. The compensated rungs keep every
    /// pixel.
    pub mask: Option<Array2<bool>>,
    /// The joint fit ([`crate::joint`]) of the pair's dense flow, from the
    /// field measured, when asked for.
    pub joint: Option<JointSettings>,
}

impl Default for LadderSettings {
    fn default() -> Self {
        LadderSettings {
            separations: SEPARATIONS.to_vec(),
            bootstrap_longest: BOOTSTRAP_LONGEST,
            bootstrap_reach: BOOTSTRAP_REACH,
            piv: Settings {
                clip: spiv_piv::Clip::Off,
                highpass: 0.0,
                ..Settings::for_compensated_frames()
            },
            mask: None,
            joint: None,
        }
    }
}

/// One rung as it went.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Rung {
    /// Separation (and window), ticks.
    pub separation: u32,
    /// Valid, replaced and invalid vectors of its PIV.
    pub counts: (usize, usize, usize),
    /// Nodes whose kept vector came from this rung.
    pub kept: usize,
    /// Wall time of its frames and PIV, ms.
    pub ms: f64,
}

impl Rung {
    /// Whether its field was usable ([`spiv_piv::usable_counts`]): the
    /// ladder climbs past a rung only when it is.
    pub fn usable(&self) -> bool {
        spiv_piv::usable_counts(self.counts)
    }
}

/// A pair measured by the ladder.
#[derive(Debug, Clone)]
pub struct Measurement {
    /// The field in px per pair of the `dt` ticks asked for, each
    /// vector's uncertainty likewise in `sigma`; all invalid when no rung
    /// fit or measured.
    pub field: PerPair,
    /// The separation (ticks) of the rung each vector came from; 0 where
    /// it was replaced or is invalid.
    pub separation: Array2<u32>,
    /// The rungs climbed, shortest first.
    pub rungs: Vec<Rung>,
    /// The frames of the rung most vectors came from.
    pub frames: Option<RungFrames>,
    /// The dense flow per pixel, px per `dt` ticks, when the dense
    /// ensemble ([`ensemble`]) measured the pair or the joint fit
    /// ([`crate::joint`]) refined it.
    pub dense: Option<Flow>,
    /// Whether the first rung confirmed the flow the rung frames followed
    /// (`None`: the pair had no such flow).
    pub confirmed: Option<bool>,
    /// The dense ensemble measured the pair.
    pub ensemble: bool,
}

/// A rung's compensated frames (upright, in spikes).
#[derive(Debug, Clone)]
pub struct RungFrames {
    /// The rung's separation, ticks.
    pub separation: u32,
    /// Frame A (before the midpoint) and B (after it).
    pub frames: [Array2<f32>; 2],
}

/// What a pair's frames come from, as the core made them
/// ([`spiv_core::rungs`]): the events around its midpoint, or the rung
/// frames warped along a flow, or both.
#[derive(Debug, Clone, Default)]
pub struct PairInput {
    /// The events around the midpoint, when the pair carries them (a pair
    /// made with no flow to follow, or one that asked for them).
    pub events: Option<Events>,
    /// The flow the rung frames follow: node velocities on the grid of
    /// the ladder's PIV.
    pub start: Option<PerTick>,
    /// The rung frames along `start`, shortest separation first: the
    /// separation (ticks) and frames A (before the midpoint) and B (after
    /// it), upright, in spikes.
    pub rungs: Vec<(u32, [Array2<f32>; 2])>,
}

impl PairInput {
    /// A pair of only its events.
    pub fn of_events(events: Events) -> PairInput {
        PairInput {
            events: Some(events),
            ..PairInput::default()
        }
    }
}

/// The state of one pair's climb: the kept vectors, where each came from,
/// the estimate the next rung follows, and the rungs so far.
struct Climb {
    best: Option<Field>,
    separation: Option<Array2<u32>>,
    estimate: Option<Field>,
    change: Option<Array2<Step>>,
    /// The estimate comes from compensated rungs or a given start (not
    /// from the uncompensated bootstrap rungs alone).
    compensated: bool,
    rungs: Vec<Rung>,
    frames: Option<RungFrames>,
    dt: f64,
}

impl Climb {
    fn new(estimate: Option<Field>, dt: f64) -> Climb {
        Climb {
            compensated: estimate.is_some(),
            best: None,
            separation: None,
            estimate,
            change: None,
            rungs: Vec::new(),
            frames: None,
            dt,
        }
    }

    /// Adds rung `s`'s field `f` (over `s` ticks) and frames; returns
    /// whether the rung measured (its field is usable).
    fn add(
        &mut self,
        s: u32,
        f: &Field,
        frames: [Array2<f32>; 2],
        ms: f64,
        longest_bootstrap: u32,
    ) -> bool {
        let counts = f.counts();
        let measured = f.usable();
        let rung = per_tick(f, f64::from(s.max(2)));
        if self.estimate.is_some() && s > longest_bootstrap {
            unconfirmed(&mut self.best, &self.separation, &rung, longest_bootstrap);
        }
        let kept = keep(&mut self.best, &mut self.separation, &rung, s);
        // A step from an estimate of the uncompensated rungs measures
        // their blur, not this rung's model error: it is not recorded.
        let estimate = self.estimate.as_ref().filter(|_| self.compensated);
        changes(&mut self.change, &self.separation, &rung, estimate, s);
        if self.rungs.iter().all(|r| r.kept < kept) {
            self.frames = Some(RungFrames {
                separation: s,
                frames,
            });
        }
        self.rungs.push(Rung {
            separation: s,
            counts,
            kept,
            ms,
        });
        if measured {
            self.compensated |= self.estimate.is_some();
            self.estimate = self.best.as_ref().map(|b| finished(b, self.dt));
        }
        measured
    }
}

/// Measures the flow at time `mid` (a tick boundary: A ends and B begins
/// there) from `input`, in px per `dt` ticks.
///
/// With rung frames along a flow (`input.start`), each rung is measured by
/// PIV predicted by the estimate so far (the start, then the kept field),
/// shortest first; the first rung must confirm the start (`confirms`).
/// A start it does not confirm is dropped: the pair climbs from its
/// events as an unestimated pair does when it carries them, else from the
/// first rung's own field. Without rung frames, the pair climbs from its
/// events: the uncompensated rungs up to
/// [`LadderSettings::bootstrap_longest`], then rungs compensated along
/// the estimate so far, as far as the events reach (with `rescue`, on to
/// the longest rung they hold: `separations_held`); then once more,
/// every rung compensated along the estimate that climb reached. Every
/// kept vector's uncertainty includes its change from the estimate that
/// predicted its rung.
///
/// A field that is not usable is measured again by the dense ensemble;
/// with `rescue`, so is a usable one with more than [`ENSEMBLE_FLAGGED`]
/// of its vectors flagged (a pair that only starts the next one leaves
/// `rescue` off: the next pair's first rung confirms or drops its field).
/// A pair that kept no field and that the ensemble does not measure
/// climbs its events once more from rest (`from_rest`).
///
/// With [`LadderSettings::joint`], a pair measured for itself (`rescue`)
/// with events and a usable field or the ensemble's dense flow has its
/// dense flow refined by the joint fit ([`crate::joint::fit`]) of every
/// short frame within its reach: [`Measurement::dense`] is then the flow
/// it started from plus the fit's correction, both carried along their
/// paths over `dt`.
pub fn measure(
    input: &PairInput,
    mid: u64,
    dt: Ticks,
    cfg: &LadderSettings,
    (w, h): (usize, usize),
    rescue: bool,
) -> Result<Measurement, crate::Error> {
    let mut m = measure_field(input, mid, dt, cfg, (w, h), rescue)?;
    // The joint fit refines the dense flow of a pair measured for itself,
    // from the ensemble's flow or the field's vectors between the nodes.
    if let (Some(joint), Some(ev), true) = (&cfg.joint, &input.events, rescue) {
        let measured = m.dense.is_some() || m.field.usable();
        if measured && (ev.width, ev.height) == (w, h) {
            let Ticks(d) = dt;
            let start = match &m.dense {
                Some(f) => Velocity::from_displacement(&f.u, &f.v, d),
                None => dense_velocity(&m.field.per_tick(), h, w),
            };
            if let Some(vel) = crate::joint::fit(ev, mid, &start, joint) {
                let (u, v) = vel.displacements(d);
                m.dense = Some(match m.dense.take() {
                    // The fit's correction, carried along the paths, added
                    // to the ensemble's dense flow it started from.
                    Some(base) => {
                        let (u0, v0) = start.displacements(d);
                        Flow {
                            u: base.u + &u - &u0,
                            v: base.v + &v - &v0,
                        }
                    }
                    None => Flow { u, v },
                });
            }
        }
    }
    Ok(m)
}

/// [`measure`] before the joint fit.
fn measure_field(
    input: &PairInput,
    mid: u64,
    dt: Ticks,
    cfg: &LadderSettings,
    (w, h): (usize, usize),
    rescue: bool,
) -> Result<Measurement, crate::Error> {
    let Ticks(dt) = dt;
    let mut confirmed = None;
    let climb = match (&input.start, input.rungs.is_empty()) {
        (Some(start), false) => {
            // With its events too, the pair climbs from them first and the
            // rung frames go on from where they left it.
            let from = match &input.events {
                Some(ev) => cold(ev, mid, dt, cfg)?,
                None => Climb::new(Some(start.0.clone()), dt),
            };
            let (c, ok) = warm(input, start, from, dt, cfg)?;
            confirmed = Some(ok);
            c
        }
        _ => match &input.events {
            Some(ev) => {
                // A pair measured for itself climbs on to the longest rung
                // its events hold; one that only starts the next pair
                // climbs the asked rungs (the next pair's rung frames go
                // further).
                let reach = if rescue { Reach::Held } else { Reach::Asked };
                let first = climb_events(ev, mid, cfg, Climb::new(None, dt), reach)?;
                again(ev, mid, dt, cfg, first, reach)?
            }
            None => Climb::new(None, dt),
        },
    };
    let Climb {
        best,
        separation,
        change,
        rungs,
        frames,
        ..
    } = climb;
    let best = best.filter(|_| !refuted(&rungs));
    let Some(best) = best else {
        if let Some(m) = ensemble_pair(input, mid, dt, cfg, &rungs)? {
            return Ok(Measurement { confirmed, ..m });
        }
        let m = match from_rest(input, mid, dt, cfg, (w, h), rescue, &rungs)? {
            Some(m) => m,
            None => nothing((w, h), dt, cfg, rungs, confirmed)?,
        };
        return Ok(Measurement { confirmed, ..m });
    };
    let field = kept_field(best, change.as_ref(), dt, (w, h));
    let (_, _, invalid) = field.counts();
    let flagged = invalid as f64 > ENSEMBLE_FLAGGED * field.grid.len() as f64;
    if !field.usable() || (rescue && flagged) {
        if let Some(m) = ensemble_pair(input, mid, dt, cfg, &rungs)? {
            return Ok(Measurement { confirmed, ..m });
        }
    }
    Ok(Measurement {
        separation: valid_separations(separation, &field),
        field: PerPair::new(field, Ticks(dt)),
        rungs,
        frames,
        dense: None,
        confirmed,
        ensemble: false,
    })
}

/// The kept velocities `best` (per tick) as the pair's field: their model
/// error from `change` (the steps between rungs), validated and filled
/// ([`finished`]), with the resolution term, carried along their paths
/// over `dt` and flagged where their measurement is too uncertain.
fn kept_field(
    mut best: Field,
    change: Option<&Array2<Step>>,
    dt: f64,
    (w, h): (usize, usize),
) -> Field {
    let model = change.map(|c| with_change(&mut best, c));
    let mut velocity = finished(&best, dt);
    with_resolution(&mut velocity);
    let mut field = flow_map(&velocity, &dense_velocity(&velocity, h, w), dt);
    let model = model.map(|m| m.mapv(|(a, b)| (a * dt, b * dt)));
    flag_uncertain(&mut field, model.as_ref());
    field
}

/// Each node's rung separation where `field` holds a valid vector, 0
/// elsewhere.
fn valid_separations(separation: Option<Array2<u32>>, field: &Field) -> Array2<u32> {
    let mut separation = separation.unwrap_or_else(|| Array2::zeros(field.u.dim()));
    for (s, st) in separation.iter_mut().zip(field.state.iter()) {
        if *st != State::Valid {
            *s = 0;
        }
    }
    separation
}

/// The climb of a pair that neither its bootstrap rungs nor the dense
/// ensemble measured, from rest: the rungs longer than the bootstrap's,
/// uncompensated, PIV predicted by a still flow, then (as [`again`]) once
/// more along what they measured. Dim particles give the short rungs too
/// few spikes, and a slow flow leaves little for the ensemble's 6-tick
/// frames to see, yet blurs little over a longer rung: on spectral
/// turbulence's dim, slow members a 62-plane recording measured nothing,
/// and from rest measures (`docs/results.md`). The step from rest to the
/// first rung is the displacement itself, not a model error, so it is not
/// recorded. `None` when it keeps no usable field: pure noise and static
/// light still measure nothing.
fn from_rest(
    input: &PairInput,
    mid: u64,
    dt: f64,
    cfg: &LadderSettings,
    (w, h): (usize, usize),
    rescue: bool,
    before: &[Rung],
) -> Result<Option<Measurement>, crate::Error> {
    let Some(ev) = &input.events else {
        return Ok(None);
    };
    let grid = grid_of(w, h, cfg)?;
    let still = Field {
        state: Array2::from_elem((grid.ny, grid.nx), State::Valid),
        sigma: Array2::from_elem((grid.ny, grid.nx), (0.0, 0.0)),
        ..Field::unmeasured(grid)
    };
    let longer = LadderSettings {
        separations: cfg
            .separations
            .iter()
            .copied()
            .filter(|&s| s > cfg.bootstrap_longest)
            .collect(),
        ..cfg.clone()
    };
    let reach = if rescue { Reach::Held } else { Reach::Asked };
    let rest = Climb {
        compensated: false,
        ..Climb::new(Some(still), dt)
    };
    let first = climb_events(ev, mid, &longer, rest, reach)?;
    let Climb {
        best,
        separation,
        change,
        rungs,
        frames,
        ..
    } = again(ev, mid, dt, &longer, first, reach)?;
    let Some(best) = best else {
        return Ok(None);
    };
    let field = kept_field(best, change.as_ref(), dt, (w, h));
    if !field.usable() {
        return Ok(None);
    }
    Ok(Some(Measurement {
        separation: valid_separations(separation, &field),
        field: PerPair::new(field, Ticks(dt)),
        rungs: before.iter().copied().chain(rungs).collect(),
        frames,
        dense: None,
        confirmed: None,
        ensemble: false,
    }))
}

/// Whether the climb's field rests on its first rung alone while a longer
/// rung, compensated along that rung's field, measured nothing at all: a
/// right field carries the longer rung's frames onto each other. On dim
/// particles the shortest rung is shorter than their pixels' spike period
/// (a pixel that fired in A cannot fire again in B), the correlation dips
/// at zero lag, and its peak sits a particle radius off on every window:
/// confidently wrong (`docs/results.md`, spectral turbulence).
fn refuted(rungs: &[Rung]) -> bool {
    let Some(first) = rungs.first() else {
        return false;
    };
    let rest = &rungs[1..];
    first.kept > 0
        && rest.iter().all(|r| r.kept == 0)
        && rest
            .iter()
            .any(|r| r.separation > first.separation && r.counts.0 == 0)
}

/// The climb over the rung frames along `start`, on from `from` (the
/// climb of the pair's events, or nothing yet); whether the first rung
/// confirmed the start (when it did not, `from` as it was).
fn warm(
    input: &PairInput,
    start: &Field,
    from: Climb,
    dt: f64,
    cfg: &LadderSettings,
) -> Result<(Climb, bool), PivError> {
    let _ = dt;
    let mut climb = from;
    let mut confirmed = true;
    let mut distrust: Option<Array2<bool>> = None;
    for (k, (s, [a, b])) in input.rungs.iter().enumerate() {
        let t0 = std::time::Instant::now();
        let e = climb.estimate.clone().unwrap_or_else(|| start.clone());
        let mut f = predicted_rung(a, b, u64::from(*s), &e, cfg)?;
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        if k == 0 {
            let first = per_tick(&f, f64::from((*s).max(2)));
            if !confirms(&first, start) {
                confirmed = false;
                if input.events.is_some() {
                    return Ok((climb, false));
                }
                // No events to start again from: the first rung's own
                // field is the estimate from here on.
                climb.estimate = None;
            } else {
                distrust = Some(departed(&first, start));
            }
        } else if let Some(d) = &distrust {
            // Where the first rung left the flow, the longer rungs' frames
            // were warped along a wrong path: their vectors there are not
            // kept.
            for (st, &no) in f.state.iter_mut().zip(d.iter()) {
                if no {
                    *st = State::Invalid;
                }
            }
        }
        let measured = climb.add(*s, &f, [a.clone(), b.clone()], ms, cfg.bootstrap_longest);
        if !measured {
            break;
        }
    }
    Ok((climb, confirmed))
}

/// The climb of a pair from its events alone, over the asked rungs (its
/// rung frames go on from there).
fn cold(ev: &Events, mid: u64, dt: f64, cfg: &LadderSettings) -> Result<Climb, PivError> {
    climb_events(ev, mid, cfg, Climb::new(None, dt), Reach::Asked)
}

/// A pair with no flow to follow climbs its events a second time along
/// the estimate its first climb reached: every rung, the shortest too, is
/// then compensated, where the first climb's bootstrap rungs were blurred
/// by the motion (a third climb gains nothing: docs/results.md). The
/// second climb stands when it keeps at least as many valid vectors as
/// the first (at a recording's clipped ends it can keep fewer). `reach`
/// as the first climb's.
fn again(
    ev: &Events,
    mid: u64,
    dt: f64,
    cfg: &LadderSettings,
    first: Climb,
    reach: Reach,
) -> Result<Climb, PivError> {
    let Some(e) = first.estimate.clone() else {
        return Ok(first);
    };
    let mut second = climb_events(ev, mid, cfg, Climb::new(Some(e), dt), reach)?;
    let valid = |c: &Climb| c.best.as_ref().map_or(0, |b| b.counts().0);
    if valid(&second) < valid(&first) {
        return Ok(first);
    }
    // The second climb follows the first's estimate from the same events:
    // how little it changes that estimate is no sign of how right it is.
    // The uncertainty keeps the first climb's changes (none where its
    // node came from a rung no estimate predicted: the correlation's
    // statistics stand whole there).
    second.change = first.change;
    Ok(second)
}

/// How far a climb over a pair's events goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Reach {
    /// The asked separations the events hold: beside a pair's rung frames
    /// (they go on from there), and for a warm-up pair (the next pair's
    /// rung frames do).
    Asked,
    /// On to the longest rung the events hold ([`separations_held`]): the
    /// events are all the pair has.
    Held,
}

/// The climb over `ev`'s rungs on from `climb`: compensated along its
/// estimate (and along what each rung adds) or, without one, from the
/// bootstrap rungs.
fn climb_events(
    ev: &Events,
    mid: u64,
    cfg: &LadderSettings,
    mut climb: Climb,
    reach: Reach,
) -> Result<Climb, PivError> {
    let span = ev.range();
    let mut separations = separations_held(&cfg.separations, mid, &span);
    if reach == Reach::Asked {
        separations.retain(|s| cfg.separations.contains(s));
    }
    for s in separations {
        let s64 = u64::from(s.max(2));
        if climb.estimate.is_none() && s > cfg.bootstrap_longest {
            break;
        }
        let t0 = std::time::Instant::now();
        let (f, frames) = match &climb.estimate {
            None => bootstrap_rung(ev, mid, s64, cfg)?,
            Some(e) => {
                let flow = WarpFlow::from_field(e, ev.height, ev.flip);
                let sf = s64 as f64;
                let a = ev.frame(mid as f64 - sf / 2.0, (mid - s64, s64), &flow);
                let b = ev.frame(mid as f64 + sf / 2.0, (mid, s64), &flow);
                let f = predicted_rung(&a, &b, s64, e, cfg)?;
                (f, [a, b])
            }
        };
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        let had_estimate = climb.estimate.is_some();
        let measured = climb.add(s, &f, frames, ms, cfg.bootstrap_longest);
        if !measured && had_estimate {
            break;
        }
    }
    Ok(climb)
}

/// Longest rung past the configured separations that the events hold,
/// as a share of the last one that fits: below it the extra rung gathers
/// too little more light to be worth its PIV.
const HELD_GAIN: f64 = 1.25;

/// The separations of `asked` (shortest first) whose frames the events
/// of `span` hold around `mid` — `s` ticks before it and `s` after —
/// then, when the next asked one does not fit, the longest that does if
/// it is at least [`HELD_GAIN`] times the last: a short recording's
/// central pair (62 planes: 31 ticks on each side) climbs to 31 ticks
/// instead of stopping at 16, and dim or slow particles gather twice the
/// light (`docs/results.md`, spectral turbulence).
fn separations_held(asked: &[u32], mid: u64, span: &std::ops::Range<u64>) -> Vec<u32> {
    let held = mid
        .saturating_sub(span.start)
        .min(span.end.saturating_sub(mid));
    let held = u32::try_from(held).unwrap_or(u32::MAX);
    let mut out: Vec<u32> = Vec::new();
    for &s in asked {
        if s.max(2) <= held {
            out.push(s);
            continue;
        }
        if let Some(&last) = out.last() {
            if f64::from(held) >= HELD_GAIN * f64::from(last) {
                out.push(held);
            }
        }
        break;
    }
    out
}

/// Largest share of flagged vectors in the ladder's field with which it
/// stands without asking the dense ensemble: above what the ladder flags
/// on the families it measures well, below what its usable fields on
/// large shifts flag (`docs/results.md#the-constants-and-what-chose-them`).
pub const ENSEMBLE_FLAGGED: f64 = 0.2;

/// The pair measured by the dense ensemble ([`ensemble::measure`], within
/// the bootstrap reach), in px per `dt` ticks along the paths of its mean
/// flow, after the window rungs `rungs`; `None` when it does not fit or
/// its field is not usable (the ladder's own result stands).
fn ensemble_pair(
    input: &PairInput,
    mid: u64,
    dt: f64,
    cfg: &LadderSettings,
    rungs: &[Rung],
) -> Result<Option<Measurement>, PivError> {
    let Some(ev) = &input.events else {
        return Ok(None);
    };
    let grid = grid_of(ev.width, ev.height, cfg)?;
    let t0 = std::time::Instant::now();
    let Some(e) = ensemble::measure(ev, mid, &grid, u64::from(cfg.bootstrap_reach)) else {
        return Ok(None);
    };
    let mut field = flow_map(&e.field, &e.velocity, dt);
    if !field.usable() {
        return Ok(None);
    }
    // A node is flagged by its own looks' spread, not by its neighbours'
    // pooled into its σ.
    let pool = e.pool.mapv(|(a, b)| (a * dt, b * dt));
    flag_uncertain(&mut field, Some(&pool));
    let frame = ensemble::FRAME as u32;
    let separation = field
        .state
        .mapv(|st| if st == State::Valid { frame } else { 0 });
    let (valid, _, _) = field.counts();
    let mut rungs = rungs.to_vec();
    rungs.push(Rung {
        separation: frame,
        counts: field.counts(),
        kept: valid,
        ms: t0.elapsed().as_secs_f64() * 1e3,
    });
    // Each pixel's displacement along its path, as the grid's vectors are
    // (on the tuning turbulence, seeds 1–5, 0.78–0.91 px against 0.96–1.14
    // for the velocity times dt).
    let (u, v) = e.velocity.displacements(dt);
    let dense = Flow { u, v };
    Ok(Some(Measurement {
        field: PerPair::new(field, Ticks(dt)),
        separation,
        rungs,
        frames: Some(RungFrames {
            separation: frame,
            frames: e.centre_pair(),
        }),
        dense: Some(dense),
        confirmed: None,
        ensemble: true,
    }))
}

/// The grid of the ladder's fields on a `w × h` recording.
fn grid_of(w: usize, h: usize, cfg: &LadderSettings) -> Result<Grid, PivError> {
    let size = cfg.piv.windows.last().copied().unwrap_or(32);
    cfg.piv.grid(w, h).ok_or(PivError::TooSmall(w, h, size))
}

/// The measurement of a pair no rung fits: every vector of the grid
/// invalid, with no uncertainty.
fn nothing(
    (w, h): (usize, usize),
    dt: f64,
    cfg: &LadderSettings,
    rungs: Vec<Rung>,
    confirmed: Option<bool>,
) -> Result<Measurement, PivError> {
    let grid = grid_of(w, h, cfg)?;
    Ok(Measurement {
        field: PerPair::new(Field::unmeasured(grid), Ticks(dt)),
        separation: Array2::zeros((grid.ny, grid.nx)),
        rungs,
        frames: None,
        dense: None,
        confirmed,
        ensemble: false,
    })
}

/// Rung `s` without an estimate: the uncompensated frames of consecutive
/// `s`-tick stretches within [`LadderSettings::bootstrap_reach`] of the
/// midpoint, each with the next as a pair, measured as one ensemble
/// ([`piv_ensemble`]: sparse or dim particles add up), with the rescue
/// rungs; returns its field over `s` ticks and the pair around the
/// midpoint.
fn bootstrap_rung(
    ev: &Events,
    mid: u64,
    s: u64,
    cfg: &LadderSettings,
) -> Result<(Field, [Array2<f32>; 2]), PivError> {
    let span = ev.range();
    let reach = u64::from(cfg.bootstrap_reach).max(s);
    // Stretch starts from the first whole one within reach, aligned on mid.
    let back = ((mid - span.start).min(reach) / s) * s;
    let ahead = ((span.end - mid).min(reach) / s) * s;
    let still = WarpFlow::still();
    let starts: Vec<u64> = ((mid - back)..(mid + ahead)).step_by(s as usize).collect();
    let mut frames: Vec<Array2<f32>> = starts
        .par_iter()
        .map(|&t| ev.frame(t as f64 + s as f64 / 2.0, (t, s), &still))
        .collect();
    without_static(&mut frames);
    let pairs: Vec<(&Array2<f32>, &Array2<f32>)> =
        frames.windows(2).map(|p| (&p[0], &p[1])).collect();
    let settings = Settings {
        rescue: true,
        windows: BOOTSTRAP_WINDOWS.to_vec(),
        ..cfg.piv.clone()
    };
    let f = piv_ensemble(&pairs, cfg.mask.as_ref(), &settings, None)?;
    // The pair that meets at the midpoint.
    let k = (back / s) as usize;
    let centre = [frames[k - 1].clone(), frames[k].clone()];
    Ok((f, centre))
}

/// Takes each pixel's mean over `frames` (consecutive uncompensated
/// frames) off every one of them: what the events still hold of static
/// light (the beat of a pixel its period does not quite follow) is the
/// same in every frame, and frames one after the other would correlate on
/// it where nothing moves; a particle moves across the frames and keeps
/// most of its own.
fn without_static(frames: &mut [Array2<f32>]) {
    let Some(first) = frames.first() else {
        return;
    };
    let mut mean = Array2::<f32>::zeros(first.dim());
    for f in frames.iter() {
        mean += f;
    }
    mean /= frames.len() as f32;
    for f in frames.iter_mut() {
        *f -= &mean;
    }
}

/// PIV of rung `s`'s frames `a`, `b` (warped along a flow to their own
/// centres, `s` ticks apart), predicted by the estimate `e` (velocities per
/// node): its displacement over `s` along its paths.
fn predicted_rung(
    a: &Array2<f32>,
    b: &Array2<f32>,
    s: u64,
    e: &Field,
    cfg: &LadderSettings,
) -> Result<Field, PivError> {
    let (h, w) = a.dim();
    let vel = dense_velocity(e, h, w);
    // The mask is not applied here: innovation frames hold nothing where
    // nothing moves, so a still body or wall adds no particles, and the
    // predicted deformation would move the frames against a mask drawn on
    // the undeformed image (leaving the masked pixels out here cost the
    // field away from the body 30 % in `tests/tests/masks.rs`, zeroing
    // them 28 %). The flow job makes masked nodes invalid afterwards.
    let init = flow_map(e, &vel, s as f64);
    let settings = Settings {
        rescue: false,
        ..cfg.piv.clone()
    };
    piv_predicted(a, b, None, &settings, Some(&init))
}

/// The node velocities of `e` interpolated to every pixel of an `h × w`
/// frame ([`Field::predictor`]: holes take their neighbours').
fn dense_velocity(e: &Field, h: usize, w: usize) -> Velocity {
    let (u, v) = e.predictor(h, w);
    Velocity { u, v }
}

/// `e` (velocities per node) as displacements over `ticks` ticks along the
/// paths through `vel`, `e`'s dense field, each node's uncertainty times
/// `ticks`: a PIV predictor, or the result.
fn flow_map(e: &Field, vel: &Velocity, ticks: f64) -> Field {
    let mut o = e.clone();
    for idx in ndarray::indices(e.u.dim()) {
        let (x, y) = e.grid.centre(idx.0, idx.1);
        let (du, dv) = vel.displacement((x, y), ticks);
        o.u[idx] = du;
        o.v[idx] = dv;
        let (a, b) = path_sigma(e, idx, (du, dv));
        o.sigma[idx] = (a * ticks, b * ticks);
    }
    o
}

/// The uncertainty of the displacement that starts at node `idx` and
/// moves by `(du, dv)` px: a displacement integrates the velocities along
/// its path, so it is at least as uncertain as the measured nodes the
/// straight path passes within half a grid step of (their root mean
/// square), not only its own node. A path shorter than a step keeps the
/// node's own.
fn path_sigma(e: &Field, idx: (usize, usize), (du, dv): (f64, f64)) -> (f64, f64) {
    let own = e.sigma[idx];
    let step = e.grid.step as f64;
    let len = du.hypot(dv);
    if e.state[idx] == State::Invalid || len < step || !len.is_finite() {
        return own;
    }
    let (x0, y0) = e.grid.centre(idx.0, idx.1);
    let (mut n, mut su, mut sv) = (0usize, 0.0f64, 0.0f64);
    for (r, c) in ndarray::indices(e.u.dim()) {
        let (x, y) = e.grid.centre(r, c);
        // Distance from the node to the segment (x0, y0) → (x0 + du, y0 + dv).
        let t = (((x - x0) * du + (y - y0) * dv) / (len * len)).clamp(0.0, 1.0);
        let d = (x - x0 - t * du).hypot(y - y0 - t * dv);
        let (a, b) = e.sigma[[r, c]];
        if d <= 0.5 * step && e.state[[r, c]] != State::Invalid && a.is_finite() && b.is_finite() {
            n += 1;
            su += a * a;
            sv += b * b;
        }
    }
    if n == 0 {
        return own;
    }
    let (ru, rv) = ((su / n as f64).sqrt(), (sv / n as f64).sqrt());
    (own.0.max(ru), own.1.max(rv))
}

/// The velocities a rung measured: each vector's displacement over `s`
/// ticks divided by `s` (the chord of the particle's path, centred on the
/// node: its velocity to second order in `s`), uncertainties likewise.
/// Not the estimate plus PIV's residual: the predictor follows paths
/// through the interpolated field, so the residual corrects the velocity
/// averaged along the path, not at the node.
fn per_tick(f: &Field, s: f64) -> Field {
    PerTick::from_displacements(f, Ticks(s)).0
}

/// Keeps, per node, `f`'s valid vector where it is more certain than the
/// one kept so far (the first rung starts the kept field); returns how
/// many nodes took it.
fn keep(best: &mut Option<Field>, sep: &mut Option<Array2<u32>>, f: &Field, s: u32) -> usize {
    let certain = |(a, b): (f64, f64)| {
        if a.is_finite() && b.is_finite() {
            a.hypot(b)
        } else {
            f64::INFINITY
        }
    };
    let b = best.get_or_insert_with(|| {
        let mut e = f.clone();
        e.state.fill(State::Invalid);
        e.sigma.fill(NO_SIGMA);
        e
    });
    let sp = sep.get_or_insert_with(|| Array2::zeros(f.u.dim()));
    if b.grid != f.grid {
        return 0;
    }
    let mut n = 0;
    for idx in ndarray::indices(f.u.dim()) {
        if f.state[idx] != State::Valid || certain(f.sigma[idx]) >= certain(b.sigma[idx]) {
            continue;
        }
        b.u[idx] = f.u[idx];
        b.v[idx] = f.v[idx];
        b.state[idx] = State::Valid;
        b.sigma[idx] = f.sigma[idx];
        b.peak_ratio[idx] = f.peak_ratio[idx];
        b.peak_height[idx] = f.peak_height[idx];
        sp[idx] = s;
        n += 1;
    }
    n
}

/// Largest median change, as a share of the median predicted speed, with
/// which the first rung still confirms a given start.
const START_CHANGE: f64 = 0.25;

/// Change below which any start is confirmed, px/tick: the first rung's
/// noise on a slow flow.
const START_FLOOR: f64 = 0.02;

/// Whether the first rung measured from a given start (`e`, px/tick)
/// agrees with it: the median change over the rung's valid vectors is at
/// most [`START_CHANGE`] of the median predicted speed plus
/// [`START_FLOOR`]. A start twice the truth changes by half its speed,
/// one with its sign flipped by twice it.
fn confirms(rung: &Field, e: &Field) -> bool {
    if rung.grid != e.grid {
        return false;
    }
    let mut change = Vec::new();
    let mut speed = Vec::new();
    for idx in ndarray::indices(rung.u.dim()) {
        if rung.state[idx] == State::Valid && e.state[idx] != State::Invalid {
            change.push((rung.u[idx] - e.u[idx]).hypot(rung.v[idx] - e.v[idx]));
            speed.push(e.u[idx].hypot(e.v[idx]));
        }
    }
    if change.is_empty() {
        return false;
    }
    validate::median(&mut change) <= START_CHANGE * validate::median(&mut speed) + START_FLOOR
}

/// Standard uncertainties of the first rung's vector by which it may
/// leave the start at a node before the node counts as departed.
const DEPARTED_SIGMAS: f64 = 3.0;

/// The nodes where the first rung's valid vector (`rung`, px/tick) left
/// the start `e` by more than [`START_CHANGE`] of the start's speed there
/// plus the larger of [`START_FLOOR`] and [`DEPARTED_SIGMAS`] of the
/// vector's own uncertainty: [`confirms`], node by node, beyond the
/// rung's noise.
fn departed(rung: &Field, e: &Field) -> Array2<bool> {
    let mut out = Array2::from_elem(rung.u.dim(), false);
    if rung.grid != e.grid {
        return out;
    }
    for idx in ndarray::indices(rung.u.dim()) {
        if rung.state[idx] == State::Valid && e.state[idx] != State::Invalid {
            let change = (rung.u[idx] - e.u[idx]).hypot(rung.v[idx] - e.v[idx]);
            let speed = e.u[idx].hypot(e.v[idx]);
            let (su, sv) = rung.sigma[idx];
            let noise = DEPARTED_SIGMAS * su.hypot(sv);
            let noise = if noise.is_finite() { noise } else { 0.0 };
            out[idx] = change > START_CHANGE * speed + START_FLOOR.max(noise);
        }
    }
    out
}

/// A kept vector's step from the estimate that predicted its rung, px
/// per tick: how far it moved (`by`) and the estimate's own uncertainty
/// there (`prior`); NaN where no estimate predicted the rung (the first
/// rung of a climb from nothing).
#[derive(Debug, Clone, Copy)]
struct Step {
    by: (f64, f64),
    prior: (f64, f64),
}

impl Step {
    const UNKNOWN: Step = Step {
        by: (f64::NAN, f64::NAN),
        prior: (f64::NAN, f64::NAN),
    };
}

/// Records, for each node whose kept vector came from rung `s` (`f`),
/// its [`Step`] from the estimate that predicted the rung (the shorter
/// rungs' kept field, validated and filled, or the given start): a rung
/// twice as long reads the chord of a path twice as long, whose departure
/// from the velocity at the node grows with the square of its length, so
/// the step from the shorter rungs, beyond the noise both sides carry,
/// measures the model error of the longer one that the correlation
/// statistics cannot see (and a wrong start shows as a large step).
fn changes(
    change: &mut Option<Array2<Step>>,
    sep: &Option<Array2<u32>>,
    f: &Field,
    previous: Option<&Field>,
    s: u32,
) {
    let c = change.get_or_insert_with(|| Array2::from_elem(f.u.dim(), Step::UNKNOWN));
    let Some(sp) = sep.as_ref() else {
        return;
    };
    let previous = previous.filter(|p| p.grid == f.grid);
    for idx in ndarray::indices(f.u.dim()) {
        if sp[idx] != s {
            continue;
        }
        c[idx] = match previous {
            Some(p) if p.state[idx] != State::Invalid => Step {
                by: (f.u[idx] - p.u[idx], f.v[idx] - p.v[idx]),
                prior: p.sigma[idx],
            },
            _ => Step::UNKNOWN,
        };
    }
}

/// Model error of a rung's vector per unit of its step's excess over the
/// noise: the chord's departure from the velocity grows with the square
/// of the separation, so a rung twice as long departs four times as far
/// as the estimate of half its length that predicted it, and the step
/// between them is three quarters of the longer rung's departure.
const MODEL: f64 = 4.0 / 3.0;

/// The median of a squared standard normal variable over its mean: the
/// median of the neighbourhood's squared steps, divided by it, estimates
/// their mean square without letting one outlying step decide it.
const CHI2_MEDIAN: f64 = 0.454_936_423_119_572_8;

/// Adds to each kept vector's correlation uncertainty, in quadrature, the
/// model error its rung's steps measure ([`changes`]), and returns that
/// model error per node (px per tick; zero where none). A step's excess is
/// its square less the squares of the two uncertainties it carries (the
/// rung's correlation statistics and the predicting estimate's); the
/// model error is [`MODEL`] times the root of the larger of the node's own
/// excess and the median excess over the node and its measured
/// 8-neighbours with a known step (over [`CHI2_MEDIAN`]), where positive.
/// One step is one draw of the noise: the neighbourhood measures what one
/// vector's step cannot, and a step far beyond it still counts for its
/// own node. A node whose rung no estimate predicted keeps its
/// correlation statistics alone.
fn with_change(b: &mut Field, change: &Array2<Step>) -> Array2<(f64, f64)> {
    let (ny, nx) = b.u.dim();
    let excess = |r: usize, c: usize| -> Option<(f64, f64)> {
        let st = change[[r, c]];
        let (q, p) = (b.sigma[[r, c]], st.prior);
        let e = (
            st.by.0 * st.by.0 - q.0 * q.0 - p.0 * p.0,
            st.by.1 * st.by.1 - q.1 * q.1 - p.1 * p.1,
        );
        (b.state[[r, c]] == State::Valid && e.0.is_finite() && e.1.is_finite()).then_some(e)
    };
    let excess = Array2::from_shape_fn((ny, nx), |(r, c)| excess(r, c));
    let mut model = Array2::from_elem((ny, nx), (0.0, 0.0));
    for (r, c) in ndarray::indices((ny, nx)) {
        let Some(own) = excess[[r, c]] else {
            continue;
        };
        let (mut eu, mut ev) = (Vec::with_capacity(9), Vec::with_capacity(9));
        for rr in r.saturating_sub(1)..(r + 2).min(ny) {
            for cc in c.saturating_sub(1)..(c + 2).min(nx) {
                if let Some((a, e)) = excess[[rr, cc]] {
                    eu.push(a);
                    ev.push(e);
                }
            }
        }
        let pooled =
            |x: &mut Vec<f64>, own: f64| (validate::median(x) / CHI2_MEDIAN).max(own).max(0.0);
        model[[r, c]] = (
            MODEL * pooled(&mut eu, own.0).sqrt(),
            MODEL * pooled(&mut ev, own.1).sqrt(),
        );
    }
    for (sg, &(mu, mv)) in b.sigma.iter_mut().zip(model.iter()) {
        *sg = (sg.0.hypot(mu), sg.1.hypot(mv));
    }
    model
}

/// Weight of the field's local curvature in a vector's uncertainty: a
/// window averages the flow over its side, so where the flow curves within
/// it the window's vector differs from the flow at its centre by about
/// the curvature times the window's side squared over 24 — with windows
/// twice the grid pitch, a sixth of the 4-neighbour Laplacian (the
/// vector's difference from the mean of its neighbours, times four).
const CURVATURE: f64 = 1.0 / 6.0;

/// Largest standard uncertainty of a reported vector, as a share of the
/// field's median displacement, and at least [`SIGMA_FLOOR`] px: a vector
/// less certain than that is flagged invalid, not reported.
const SIGMA_SHARE: f64 = 0.25;

/// [`SIGMA_SHARE`]'s floor, px per pair: slow flows measure to this.
const SIGMA_FLOOR: f64 = 0.5;

/// Adds the field's local curvature ([`CURVATURE`] times the
/// 4-neighbour Laplacian over measured neighbours) to each measured
/// vector's uncertainty (`f` in px per tick), in quadrature.
fn with_resolution(f: &mut Field) {
    let (ny, nx) = f.u.dim();
    let measured = |r: usize, c: usize| f.state[[r, c]] != State::Invalid;
    let mut add = Array2::from_elem((ny, nx), (0.0, 0.0));
    for (r, c) in ndarray::indices((ny, nx)) {
        if !measured(r, c) {
            continue;
        }
        let (mut lu, mut lv, mut n) = (0.0, 0.0, 0usize);
        let near = [
            (r.wrapping_sub(1), c),
            (r + 1, c),
            (r, c.wrapping_sub(1)),
            (r, c + 1),
        ];
        for (rr, cc) in near {
            if rr < ny && cc < nx && measured(rr, cc) {
                lu += f.u[[rr, cc]] - f.u[[r, c]];
                lv += f.v[[rr, cc]] - f.v[[r, c]];
                n += 1;
            }
        }
        if n > 0 {
            let k = 4.0 / n as f64 * CURVATURE;
            add[[r, c]] = (k * lu, k * lv);
        }
    }
    for ((sg, &(a, b)), st) in f.sigma.iter_mut().zip(add.iter()).zip(f.state.iter()) {
        if *st != State::Invalid {
            *sg = (sg.0.hypot(a), sg.1.hypot(b));
        }
    }
}

/// Flags (invalid, no uncertainty) every vector of `f` (px per pair) whose
/// standard uncertainty exceeds [`SIGMA_SHARE`] of the median measured
/// displacement or [`SIGMA_FLOOR`], whichever is larger: for a valid
/// vector, its uncertainty without what `model` adds to it (px per pair:
/// the model error its rung's steps measured, [`with_change`] — the
/// vector measured, and how far its rung's chord may be off is in its σ;
/// or the ensemble's neighbourhood pool), and not when its
/// valid neighbours would replace it less certainly still
/// ([`fill_uncertainty`]). When a valid vector goes, the replaced ones are
/// filled again from the valid ones left (their values and uncertainties
/// leaned on it) and flagged by the same bound.
fn flag_uncertain(f: &mut Field, model: Option<&Array2<(f64, f64)>>) {
    let mut d: Vec<f64> =
        f.u.iter()
            .zip(f.v.iter())
            .zip(f.state.iter())
            .filter(|(_, st)| **st != State::Invalid)
            .map(|((u, v), _)| u.hypot(*v))
            .collect();
    let bound = (SIGMA_SHARE * validate::median(&mut d)).max(SIGMA_FLOOR);
    let fill = fill_uncertainty(f, bound);
    let model = model.filter(|m| m.dim() == f.u.dim());
    let mut dropped = false;
    for idx in ndarray::indices(f.u.dim()) {
        let (st, sg) = (&mut f.state[idx], &mut f.sigma[idx]);
        let (mu, mv) = model
            .and_then(|m| m.get(idx))
            .copied()
            .unwrap_or((0.0, 0.0));
        let own = if *st == State::Valid {
            (sg.0 * sg.0 - mu * mu)
                .max(0.0)
                .sqrt()
                .hypot((sg.1 * sg.1 - mv * mv).max(0.0).sqrt())
        } else {
            sg.0.hypot(sg.1)
        };
        if *st != State::Invalid && own > bound && !(*st == State::Valid && own < fill[idx]) {
            dropped |= *st == State::Valid;
            *st = State::Invalid;
            *sg = NO_SIGMA;
        }
    }
    if !dropped {
        return;
    }
    let replaced = f.state.mapv(|st| st == State::Replaced);
    for (st, &r) in f.state.iter_mut().zip(replaced.iter()) {
        if r {
            *st = State::Invalid;
        }
    }
    validate::replace(&mut f.u, &mut f.v, &mut f.state, &replaced, 4);
    validate::replaced_uncertainty(&f.u, &f.v, &f.state, &mut f.sigma);
    for (st, sg) in f.state.iter_mut().zip(f.sigma.iter_mut()) {
        if *st == State::Replaced && sg.0.hypot(sg.1) > bound {
            *st = State::Invalid;
            *sg = NO_SIGMA;
        }
    }
}

/// The uncertainty (length, px) with which each valid vector of `f` whose
/// σ exceeds `bound` would be replaced from its valid neighbours whose σ
/// does not ([`validate::replaced_uncertainty`]); zero where no neighbour
/// would fill it, and for every other vector.
fn fill_uncertainty(f: &Field, bound: f64) -> Array2<f64> {
    let over = Array2::from_shape_fn(f.u.dim(), |idx| {
        f.state[idx] == State::Valid && f.sigma[idx].0.hypot(f.sigma[idx].1) > bound
    });
    let mut out = Array2::zeros(f.u.dim());
    if !over.iter().any(|&o| o) {
        return out;
    }
    let mut g = f.clone();
    for (st, &o) in g.state.iter_mut().zip(over.iter()) {
        if o || *st == State::Replaced {
            *st = State::Invalid;
        }
    }
    validate::replace(&mut g.u, &mut g.v, &mut g.state, &over, 1);
    validate::replaced_uncertainty(&g.u, &g.v, &g.state, &mut g.sigma);
    for (idx, &o) in over.indexed_iter() {
        if o {
            let (a, b) = g.sigma[idx];
            out[idx] = if g.state[idx] == State::Replaced {
                a.hypot(b)
            } else {
                0.0
            };
        }
    }
    out
}

/// Drops the kept vectors that came from an unestimated rung (separation
/// up to `longest`) where the usable compensated rung `f` found no valid
/// vector: an ensemble of uncompensated frames can lock onto chance where
/// its windows hold few particles (glare next to a corner: a cluster read
/// 5 px per pair upwards with a peak ratio of 2), and the compensated rung
/// that it predicted is the first independent look.
fn unconfirmed(best: &mut Option<Field>, sep: &Option<Array2<u32>>, f: &Field, longest: u32) {
    let (Some(b), Some(sp)) = (best.as_mut(), sep.as_ref()) else {
        return;
    };
    if b.grid != f.grid {
        return;
    }
    for idx in ndarray::indices(f.u.dim()) {
        if sp[idx] <= longest && b.state[idx] == State::Valid && f.state[idx] != State::Valid {
            b.state[idx] = State::Invalid;
            b.sigma[idx] = NO_SIGMA;
        }
    }
}

/// The kept velocities validated as a whole (rungs disagree where one of
/// them locked onto chance; the normalised median test judges them as
/// displacements over `dt`, the scale its noise floor is set for) and
/// their holes replaced from the neighbours, with their uncertainties.
fn finished(kept: &Field, dt: f64) -> Field {
    let mut f = kept.clone();
    let v = Settings::default().validation;
    let (du, dv) = (f.u.mapv(|x| x * dt), f.v.mapv(|x| x * dt));
    validate::median_test(&du, &dv, &mut f.state, v.median_threshold, v.median_eps);
    for (st, sg) in f.state.iter().zip(f.sigma.iter_mut()) {
        if *st == State::Invalid {
            *sg = NO_SIGMA;
        }
    }
    let replaceable = Array2::from_elem(f.u.dim(), true);
    validate::replace(&mut f.u, &mut f.v, &mut f.state, &replaceable, 4);
    validate::replaced_uncertainty(&f.u, &f.v, &f.state, &mut f.sigma);
    f
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rung(separation: u32, counts: (usize, usize, usize), kept: usize) -> Rung {
        Rung {
            separation,
            counts,
            kept,
            ms: 0.0,
        }
    }

    /// A 3 × 3 field of valid vectors, each with correlation
    /// uncertainty `q` (px per tick).
    fn valid_field(q: f64) -> Field {
        let grid = Grid {
            size: 32,
            step: 16,
            nx: 3,
            ny: 3,
        };
        let mut f = Field::unmeasured(grid);
        f.state.fill(State::Valid);
        f.sigma.fill((q, q));
        f
    }

    #[test]
    fn steps_within_their_noise_add_no_model_error() {
        // Steps of the size the two uncertainties they carry explain:
        // 0.05² = 0.03² + 0.04².
        let mut f = valid_field(0.03);
        let change = Array2::from_elem(
            (3, 3),
            Step {
                by: (0.05, -0.05),
                prior: (0.04, 0.04),
            },
        );
        with_change(&mut f, &change);
        for &(a, b) in &f.sigma {
            assert!(
                (a - 0.03).abs() < 1e-12 && (b - 0.03).abs() < 1e-12,
                "{a} {b}"
            );
        }
    }

    fn steps(by: f64) -> Array2<Step> {
        Array2::from_elem(
            (3, 3),
            Step {
                by: (by, 0.0),
                prior: (0.0, 0.0),
            },
        )
    }

    #[test]
    fn one_outlying_step_counts_for_its_own_node_alone() {
        // One node stepped by 0.3 px per tick, its correlation and prior
        // claiming no noise: the median of every neighbourhood's excess is
        // zero, so only the node itself carries it.
        let mut f = valid_field(0.0);
        let mut change = steps(0.0);
        change[[0, 0]].by = (0.3, 0.0);
        let model = with_change(&mut f, &change);
        assert!(
            (f.sigma[[0, 0]].0 - MODEL * 0.3).abs() < 1e-12,
            "{:?}",
            f.sigma
        );
        assert_eq!(model[[0, 0]], f.sigma[[0, 0]]);
        for idx in ndarray::indices((3, 3)) {
            if idx != (0, 0) {
                assert_eq!(f.sigma[idx], (0.0, 0.0), "{idx:?}");
            }
        }
    }

    #[test]
    fn a_neighbourhood_of_steps_measures_the_node_whose_own_step_is_small() {
        // Every node but the centre stepped by 0.3 px per tick: the centre
        // takes the neighbourhood's median square over its mean's share.
        let mut f = valid_field(0.0);
        let mut change = steps(0.3);
        change[[1, 1]].by = (0.0, 0.0);
        with_change(&mut f, &change);
        let centre = MODEL * (0.09f64 / CHI2_MEDIAN).sqrt();
        assert!((f.sigma[[1, 1]].0 - centre).abs() < 1e-12, "{:?}", f.sigma);
        // A node no estimate predicted keeps its correlation statistics.
        let mut g = valid_field(0.02);
        with_change(&mut g, &Array2::from_elem((3, 3), Step::UNKNOWN));
        assert!(g.sigma.iter().all(|&s| s == (0.02, 0.02)));
    }

    #[test]
    fn a_vector_uncertain_only_by_its_model_error_is_not_flagged() {
        // Displacements of 4 px per pair: the bound is 1 px. The centre's
        // σ of 2 px is all model error (its rung's chord), the corner's
        // measurement itself is that uncertain.
        let mut f = valid_field(0.1);
        f.u.fill(4.0);
        f.sigma[[1, 1]] = (2.0, 0.1);
        f.sigma[[0, 0]] = (2.0, 0.1);
        let mut model = Array2::from_elem((3, 3), (0.0, 0.0));
        model[[1, 1]] = (2.0, 0.0);
        flag_uncertain(&mut f, Some(&model));
        assert_eq!(f.state[[1, 1]], State::Valid);
        assert_eq!(f.sigma[[1, 1]], (2.0, 0.1), "its σ as measured");
        assert_ne!(f.state[[0, 0]], State::Valid);
    }

    #[test]
    fn a_vector_its_neighbours_would_fill_less_certainly_is_not_flagged() {
        // The centre's σ of 1.5 px is over the 1 px bound, but its
        // neighbours disagree by ±3 px: their fill would be less certain.
        let mut f = valid_field(0.1);
        f.u.fill(4.0);
        for (c, u) in [(0, 1.0), (2, 7.0)] {
            for r in 0..3 {
                f.u[[r, c]] = u;
            }
        }
        f.sigma[[1, 1]] = (1.5, 0.1);
        flag_uncertain(&mut f, None);
        assert_eq!(f.state[[1, 1]], State::Valid);
        // Neighbours that agree would fill it better: it goes.
        let mut g = valid_field(0.1);
        g.u.fill(4.0);
        g.sigma[[1, 1]] = (1.5, 0.1);
        flag_uncertain(&mut g, None);
        assert_ne!(g.state[[1, 1]], State::Valid);
    }

    /// A short recording's central pair (62 planes, midpoint 31) climbs
    /// to the 31 ticks it holds on each side; a rung barely longer than
    /// the last that fits is not worth its PIV, and a pair that holds no
    /// asked rung climbs none.
    #[test]
    fn the_events_climb_to_the_longest_rung_they_hold() {
        let asked = SEPARATIONS;
        assert_eq!(separations_held(&asked, 31, &(0..62)), [4, 8, 16, 31]);
        // A cold pair of a long recording: its events reach 32 on each side.
        assert_eq!(separations_held(&asked, 100, &(68..132)), [4, 8, 16, 32]);
        // 38 ticks: less than a quarter more than 32.
        assert_eq!(separations_held(&asked, 100, &(62..200)), [4, 8, 16, 32]);
        assert_eq!(
            separations_held(&asked, 100, &(60..140)),
            [4, 8, 16, 32, 40]
        );
        assert_eq!(separations_held(&asked, 10, &(0..200)), [4, 8, 10]);
        assert_eq!(separations_held(&asked, 9, &(0..200)), [4, 8]);
        assert!(separations_held(&asked, 3, &(0..200)).is_empty());
        assert!(separations_held(&asked, 300, &(0..200)).is_empty());
    }

    /// A field from the first rung alone is refuted by a longer rung that
    /// measured nothing at all; not when a longer rung kept vectors, nor
    /// when the longer rung measured some (its own vectors were not
    /// better), nor when no longer rung fit.
    #[test]
    fn a_lone_first_rung_is_refuted_by_a_longer_rung_that_measured_nothing() {
        let dim = [rung(4, (78, 147, 0), 78), rung(8, (0, 0, 225), 0)];
        assert!(refuted(&dim));
        let confirmed = [rung(4, (83, 142, 0), 83), rung(8, (162, 63, 0), 154)];
        assert!(!refuted(&confirmed));
        let weaker = [rung(4, (102, 123, 0), 102), rung(8, (40, 60, 125), 0)];
        assert!(!refuted(&weaker));
        assert!(!refuted(&dim[..1]));
        assert!(!refuted(&[]));
        let nothing_first = [rung(4, (0, 0, 225), 0), rung(8, (0, 0, 225), 0)];
        assert!(!refuted(&nothing_first));
    }
}

//! `spiv bench flows`: every scene family through `spiv flow`
//! with its defaults, against the dense truth, beside the frame camera and
//! a TFP pair of the same spikes through `spiv piv`'s defaults.
//!
//! Each pair's truth is the displacement over the pair of the particle at
//! each vector's centre halfway through ([`Scene::truth_at`], at the pair's
//! own middle tick: the spectral turbulence evolves; every other family is
//! steady). Per family and seed it
//! reports the end-point error (EPE, px per pair) of the measured (valid or
//! replaced) vectors in the glare rows (centres within 2σ of the wall,
//! docs/spec.md §7; the bottom rows where a scene has no glare) and in the other
//! rows, the share of vectors flagged invalid, the share of true error
//! components within one standard uncertainty (valid vectors; the frame
//! camera's and TFP's PIV report one too), the dense EPE (the field
//! interpolated to every pixel, as optical-flow benchmarks score it) and the
//! time per pair. Methods are tuned on seeds 1–5 and reported on seeds
//! 101–110, which no tuning looks at.

use std::time::Instant;

use spiv_core::{Method, Params};
use spiv_firmware_sim::scene::{Scene, SceneKind, SceneParams, Sheet};
use spiv_firmware_sim::simulation::{simulate_planes, Request};
use spiv_formats::dense::DenseField;
use spiv_formats::{State, Vector};

use crate::flow::{run_flow, FlowOptions, Recording};
use crate::piv::options::PivOptions;
use crate::piv::{deform, piv, to_f32, Field};
use crate::reconstruct::{frame_from_planes, Planes};
use crate::Error;

/// One family of scenes: a scene, its speed and the recording's length.
#[derive(Debug, Clone, PartialEq)]
pub struct Family {
    /// Name in the table.
    pub name: String,
    /// The scene.
    pub scene: SceneKind,
    /// Top speed, px/tick (`None`: the scene's default).
    pub speed: Option<f64>,
    /// Planes in the recording (the pair at its centre).
    pub ticks: u32,
}

impl Family {
    /// The member [`spectral_member`] draws for `seed` where the family's
    /// seeds are members of their own (the spectral turbulence).
    pub fn member(&self, seed: u64) -> Option<Member> {
        (self.scene == SceneKind::SpectralTurbulence).then(|| spectral_member(seed))
    }

    /// The scene parameters of the family's member `seed`: the scene's
    /// defaults (or its [`Family::member`]'s) at the family's speed with
    /// the seed's flow.
    pub fn params(&self, seed: u64) -> SceneParams {
        let mut p = self
            .member(seed)
            .map_or_else(|| SceneParams::new(self.scene), |m| m.params());
        if let Some(s) = self.speed {
            p.top_speed = s;
        }
        p.flow_seed = seed;
        p
    }
}

/// One member of the spectral-turbulence family: what varies from seed to
/// seed, each drawn from the seed over the span the third-party DNS
/// recordings and their cousins cover.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Member {
    /// The smallest eddy (half a wavelength, where the dissipation range
    /// begins), px: log-uniform in [4, 32].
    pub smallest_eddy: f64,
    /// Rms displacement per pair (21 ticks), px: log-uniform in [0.5, 8].
    pub rms_shift: f64,
    /// Particles per 32×32 cell at least: 6 to 16.
    pub per_cell: usize,
    /// Particle e⁻² diameters, px: from d to d + 2, d uniform in [2.5, 4.5].
    pub diameter: (f64, f64),
    /// Mean particle light, thresholds/tick (the sensor's threshold seen
    /// from the particle): log-uniform in [0.1, 0.4].
    pub particle_peak: f64,
    /// Light-sheet thickness (e⁻² full width), px: uniform in [12, 24].
    pub sheet: f64,
    /// Rms out-of-plane travel per pair as a fraction of the sheet's
    /// thickness: uniform in [0.05, 0.25].
    pub out_of_plane: f64,
    /// The modes' turnover rate ([`spiv_firmware_sim::scene::flow::evolving`]):
    /// uniform in [0.5, 1.5].
    pub evolution: f64,
}

/// The spectral-turbulence member of `seed`.
pub fn spectral_member(seed: u64) -> Member {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed ^ 0x7370_6563_7472);
    let mut u = || rng.gen::<f64>();
    let smallest_eddy = 4.0 * 8f64.powf(u());
    let rms_shift = 0.5 * 16f64.powf(u());
    let per_cell = 6 + (u() * 11.0).floor().min(10.0) as usize;
    let d = 2.5 + 2.0 * u();
    let particle_peak = 0.1 * 4f64.powf(u());
    let sheet = 12.0 + 12.0 * u();
    let out_of_plane = 0.05 + 0.2 * u();
    let evolution = 0.5 + u();
    Member {
        smallest_eddy,
        rms_shift,
        per_cell,
        diameter: (d, d + 2.0),
        particle_peak,
        sheet,
        out_of_plane,
        evolution,
    }
}

impl Member {
    /// The scene of this member (flow seed left to the caller).
    pub fn params(&self) -> SceneParams {
        let base = SceneParams::new(SceneKind::SpectralTurbulence);
        let dt = f64::from(base.pair_dt.max(1));
        SceneParams {
            eddies: (self.smallest_eddy, base.eddies.1),
            rms_shift: Some(self.rms_shift),
            per_cell: self.per_cell,
            // Dense seeding needs closer centres (16 per cell: one per 64
            // px², 4.5 px apart at most on average).
            min_spacing: if self.per_cell > 10 { 4.0 } else { 5.0 },
            diameter: self.diameter,
            particle_peak: self.particle_peak,
            evolution: self.evolution,
            sheet: Some(Sheet {
                thickness: self.sheet,
                depth: 2.0 * self.sheet,
                w_rms: self.out_of_plane * self.sheet / dt,
            }),
            ..base
        }
    }
}

/// The families: the paper's three (1.25 px/tick in the free stream),
/// the log profile again at 0.3 and 1 px/tick (a wall-bounded shear with
/// the glare at the wall, where the velocity falls to zero), Blasius,
/// uniform, the Lamb–Oseen vortex, the turbulence and large-shift
/// recordings as the third-party spike-flow sets hold them (62 planes,
/// pairs 21 ticks apart), the vortex array over glare at 0.3 and 1
/// px/tick, and the spectral turbulence, whose every seed is another
/// member ([`spectral_member`]), recorded as the turbulence family.
pub fn families() -> Vec<Family> {
    let f = |name: &str, scene, speed, ticks| Family {
        name: name.into(),
        scene,
        speed,
        ticks,
    };
    vec![
        f("paper-linear", SceneKind::PaperLinear, None, 300),
        f("paper-quadratic", SceneKind::PaperQuadratic, None, 300),
        f("paper-log", SceneKind::PaperLog, None, 300),
        f("paper-log 0.3", SceneKind::PaperLog, Some(0.3), 300),
        f("paper-log 1.0", SceneKind::PaperLog, Some(1.0), 300),
        f("blasius", SceneKind::Blasius, None, 300),
        f("uniform", SceneKind::Uniform, None, 300),
        f("vortex", SceneKind::Vortex, None, 300),
        f("turbulence", SceneKind::Turbulence, None, 62),
        f("large-shift", SceneKind::LargeShift, None, 62),
        f("vortex-array 0.3", SceneKind::VortexArray, Some(0.3), 160),
        f("vortex-array 1.0", SceneKind::VortexArray, Some(1.0), 160),
        f(
            "spectral turbulence",
            SceneKind::SpectralTurbulence,
            None,
            62,
        ),
    ]
}

/// One method on one recording.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct FlowsRow {
    /// Family.
    pub family: String,
    /// Seed of particles, noise and flow.
    pub seed: u64,
    /// "spiv flow" (or "spiv flow --dense"), "frame camera" or "TFP 8".
    pub method: String,
    /// Mean EPE of the measured vectors in the glare rows, px per pair.
    pub glare: Option<f64>,
    /// Mean EPE of the measured vectors in the other rows, px per pair.
    pub other: Option<f64>,
    /// Mean EPE of every measured vector, glare and other rows, px per
    /// pair: what the table's worst member is chosen by.
    pub measured: Option<f64>,
    /// Share of vectors flagged invalid.
    pub flagged: f64,
    /// Share of error components within 1σ (valid vectors with a finite
    /// uncertainty); `None` without any.
    pub coverage: Option<f64>,
    /// Share of the same vectors confidently wrong: off by more than 0.3
    /// px and by more than 3σ in u or v; `None` without any.
    pub beyond_3sigma: Option<f64>,
    /// EPE of the field interpolated to every pixel, px per pair.
    pub dense: Option<f64>,
    /// Mean truth displacement over the vectors, px per pair.
    pub mean_truth: f64,
    /// Wall time per pair, ms.
    pub ms_per_pair: f64,
    /// The family's member, where its seeds draw one.
    pub member: Option<Member>,
}

/// The row (one family's member: a seed) whose measured vectors are
/// furthest off on average; `None` when no row measured any.
pub fn worst<'r>(rows: &[&'r FlowsRow]) -> Option<&'r FlowsRow> {
    rows.iter()
        .copied()
        .filter(|r| r.measured.is_some_and(f64::is_finite))
        .max_by(|a, b| {
            a.measured
                .unwrap_or(0.0)
                .total_cmp(&b.measured.unwrap_or(0.0))
        })
}

/// Errors of a field against the truth.
#[derive(Debug, Default)]
pub(crate) struct Score {
    glare: (f64, usize),
    other: (f64, usize),
    flagged: usize,
    covered: (usize, usize),
    /// Valid vectors with a finite uncertainty off by more than 0.3 px and
    /// 3σ, and all of them.
    beyond: (usize, usize),
    truth: f64,
    all: usize,
}

impl Score {
    /// Scores `vs` (with their uncertainties) against the truth of a pair
    /// `dt` ticks apart centred on tick `mid`.
    pub(crate) fn add(
        &mut self,
        scene: &Scene,
        (mid, dt): (f64, f64),
        vs: &[Vector],
        sigma: Option<&[(f64, f64)]>,
    ) {
        let h = f64::from(scene.params.height);
        let band = 2.0 * scene.params.glare_sigma;
        let pts: Vec<(f64, f64)> = vs.iter().map(|v| (v.x, v.y)).collect();
        for (k, (v, t)) in vs.iter().zip(scene.truth_at(&pts, mid, dt)).enumerate() {
            self.all += 1;
            self.truth += t.2.hypot(t.3);
            if !v.state.is_measured() {
                self.flagged += 1;
                continue;
            }
            let (eu, ev) = (v.u - t.2, v.v - t.3);
            let slot = if h - 0.5 - v.y < band {
                &mut self.glare
            } else {
                &mut self.other
            };
            slot.0 += eu.hypot(ev);
            slot.1 += 1;
            let s = sigma.and_then(|s| s.get(k)).copied();
            if let (State::Valid, Some((su, sv))) = (v.state, s) {
                if su.is_finite() && sv.is_finite() {
                    self.covered.0 += usize::from(eu.abs() <= su) + usize::from(ev.abs() <= sv);
                    self.covered.1 += 2;
                    let far = eu.hypot(ev) > 0.3 && (eu.abs() > 3.0 * su || ev.abs() > 3.0 * sv);
                    self.beyond.0 += usize::from(far);
                    self.beyond.1 += 1;
                }
            }
        }
    }

    /// Mean EPE of every measured vector, glare and other rows together.
    pub(crate) fn measured_epe(&self) -> Option<f64> {
        let n = self.glare.1 + self.other.1;
        (n > 0).then(|| (self.glare.0 + self.other.0) / n as f64)
    }

    pub(crate) fn row(
        &self,
        family: &str,
        seed: u64,
        method: &str,
        dense: Option<f64>,
        ms: f64,
    ) -> FlowsRow {
        let mean = |(s, n): (f64, usize)| (n > 0).then(|| s / n as f64);
        FlowsRow {
            family: family.into(),
            seed,
            method: method.into(),
            glare: mean(self.glare),
            other: mean(self.other),
            measured: self.measured_epe(),
            flagged: self.flagged as f64 / self.all.max(1) as f64,
            coverage: (self.covered.1 > 0).then(|| self.covered.0 as f64 / self.covered.1 as f64),
            beyond_3sigma: (self.beyond.1 > 0).then(|| self.beyond.0 as f64 / self.beyond.1 as f64),
            dense,
            mean_truth: self.truth / self.all.max(1) as f64,
            ms_per_pair: ms,
            member: None,
        }
    }
}

/// The dense EPE of a field on `grid` (u, v, states as vectors), with
/// unmeasured nodes taking their neighbours' values.
fn dense_epe(f: &Field, truth: &DenseField) -> f64 {
    let (h, w) = (truth.height, truth.width);
    let (u, v) = crate::piv::validate::extended(&f.u, &f.v, &f.state);
    let (du, dv) = deform::dense(&f.grid, &u, &v, h, w);
    let d = DenseField {
        width: w,
        height: h,
        u: du.iter().copied().collect(),
        v: dv.iter().copied().collect(),
    };
    d.epe(truth, None).unwrap_or(f64::NAN)
}

/// The method name of `spiv flow`'s row.
pub const SPIV_FLOW: &str = "spiv flow";

/// What `spiv flow` runs for its row.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FlowRun {
    /// `spiv flow`: its vectors, interpolated for the dense column.
    Vectors,
    /// `spiv flow --dense`: the dense field it writes, each pair's
    /// refined by the joint fit.
    Dense,
    /// `spiv flow --dense --no-joint`: the dense field as the ladder or
    /// the dense ensemble measured it.
    DenseNoJoint,
}

impl FlowRun {
    /// The method name of its row.
    pub fn name(self) -> &'static str {
        match self {
            FlowRun::Vectors => SPIV_FLOW,
            FlowRun::Dense => "spiv flow --dense",
            FlowRun::DenseNoJoint => "spiv flow --dense --no-joint",
        }
    }

    fn dense(self) -> bool {
        self != FlowRun::Vectors
    }
}

/// The rows of one family and seed: `spiv flow` with its defaults, and the
/// frame camera's and the TFP 8 pair's PIV (`spiv piv`'s defaults).
/// With `vectors`, every vector of `spiv flow`'s pairs is appended there
/// as a CSV line ([`dump`]). With a dense `run`, `spiv flow --dense`
/// instead: its dense EPE is that of the dense field it writes (the mean
/// over pairs of each pair's dense flow) against the mean of the pairs'
/// truths.
pub fn family_rows(
    fam: &Family,
    seed: u64,
    vectors: Option<&std::path::Path>,
    run: FlowRun,
) -> Result<Vec<FlowsRow>, Error> {
    let dense = run.dense();
    let p = fam.params(seed);
    let member = fam.member(seed);
    let mut req = Request::new(p.clone(), seed);
    req.ticks = Some(fam.ticks);
    let (data, sim) = simulate_planes(&req)?;
    let (w, h) = (usize::from(p.width), usize::from(p.height));
    let pair = sim.meta.capture.pair;
    let dt = f64::from(pair[1] - pair[0]);
    let mid = Scene::pair_mid(u64::from(pair[0]), u64::from(pair[1]));
    let truth = sim.scene.truth_dense_at(mid, dt);
    // The truth of each of `spiv flow`'s pairs: the capture pair's where
    // the flow is steady.
    let truth_of = |ticks: [u64; 2]| {
        let m = Scene::pair_mid(ticks[0], ticks[1]);
        if sim.scene.flow.evolves() && m != mid {
            std::borrow::Cow::Owned(sim.scene.truth_dense_at(m, dt))
        } else {
            std::borrow::Cow::Borrowed(&truth)
        }
    };
    let mut rows = Vec::new();

    let user = PivOptions::default().settings()?;
    let cam = |f: &Vec<u16>| to_f32(f, w, h);
    let planes = Planes::simulated(p.width, p.height, data.clone());
    let tfp = |k: u32| -> Result<_, Error> {
        let f = frame_from_planes(&planes, u64::from(k), Method::Tfp, 8, &Params::default())?;
        Ok(to_f32(&f.data, w, h))
    };
    for (name, a, b) in [
        ("frame camera", cam(&sim.frames[0]), cam(&sim.frames[1])),
        ("TFP 8", tfp(pair[0])?, tfp(pair[1])?),
    ] {
        let t0 = Instant::now();
        let f = piv(&a, &b, None, &user)?;
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        let mut s = Score::default();
        let sigma: Vec<(f64, f64)> = f.sigma.iter().copied().collect();
        s.add(&sim.scene, (mid, dt), &f.vectors(), Some(&sigma));
        rows.push(FlowsRow {
            member,
            ..s.row(&fam.name, seed, name, Some(dense_epe(&f, &truth)), ms)
        });
    }

    let rec = Recording::simulated(p.width, p.height, data, pair[1] - pair[0]);
    let mut opts = FlowOptions::new(&rec, pair[1] - pair[0]);
    opts.dense = dense;
    if run == FlowRun::DenseNoJoint {
        opts.joint = None;
    }
    let t0 = Instant::now();
    let out = run_flow(&rec, &opts, |_, _| {})?;
    let ms = t0.elapsed().as_secs_f64() * 1e3 / out.pairs.len().max(1) as f64;
    if let Some(path) = vectors {
        dump(path, fam, seed, &sim.scene, dt, &out)?;
    }
    let mut s = Score::default();
    let mut interpolated = 0.0;
    // `--dense` scores the mean dense field against the mean truth.
    let mut mean_truth = DenseField::zeros(truth.width, truth.height);
    for pr in &out.pairs {
        let m = Scene::pair_mid(pr.ticks[0], pr.ticks[1]);
        s.add(&sim.scene, (m, dt), &pr.vectors, Some(&pr.sigma));
        let t = truth_of(pr.ticks);
        interpolated += dense_epe(&field_of(&out.grid, pr), &t);
        if dense {
            let k = 1.0 / out.pairs.len() as f32;
            for (a, b) in mean_truth.u.iter_mut().zip(&t.u) {
                *a += k * b;
            }
            for (a, b) in mean_truth.v.iter_mut().zip(&t.v) {
                *a += k * b;
            }
        }
    }
    // `--dense` without a dense field (no pair measured a usable one):
    // the row keeps its name, with no dense EPE.
    let (name, epe) = if dense {
        (
            run.name(),
            out.mean_dense
                .as_ref()
                .and_then(|d| d.epe(&mean_truth, None)),
        )
    } else {
        (
            SPIV_FLOW,
            Some(interpolated / out.pairs.len().max(1) as f64),
        )
    };
    rows.push(FlowsRow {
        member,
        ..s.row(&fam.name, seed, name, epe, ms)
    });
    Ok(rows)
}

/// A pair's vectors as a field on `grid`.
fn field_of(grid: &crate::piv::Grid, pr: &crate::flow::PairResult) -> Field {
    let shape = (grid.ny, grid.nx);
    let at = |f: &dyn Fn(&Vector) -> f64| {
        ndarray::Array2::from_shape_fn(shape, |(r, c)| {
            pr.vectors.get(r * grid.nx + c).map_or(0.0, f)
        })
    };
    Field {
        grid: *grid,
        u: at(&|v| v.u),
        v: at(&|v| v.v),
        state: ndarray::Array2::from_shape_fn(shape, |(r, c)| {
            pr.vectors
                .get(r * grid.nx + c)
                .map_or(State::Invalid, |v| v.state)
        }),
        peak_ratio: ndarray::Array2::zeros(shape),
        peak_height: ndarray::Array2::zeros(shape),
        sigma: ndarray::Array2::from_shape_fn(shape, |(r, c)| {
            pr.sigma
                .get(r * grid.nx + c)
                .copied()
                .unwrap_or(crate::piv::NO_SIGMA)
        }),
    }
}

/// Appends every vector of every pair as a CSV line to `path` (no
/// header): family, seed, pair, x, y, flag, error u and v, σu, σv, the
/// field's discrete Laplacian in u and v (the sum of the four neighbours'
/// differences, px), the separation of its rung, the truth's length, the
/// measured u and v —
/// the data an uncertainty model is fitted on (tuning seeds only).
pub fn dump(
    path: &std::path::Path,
    fam: &Family,
    seed: u64,
    scene: &Scene,
    dt: f64,
    out: &crate::flow::FlowOutcome,
) -> Result<(), Error> {
    use std::io::Write;
    let mut f = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .map_err(spiv_formats::io_err(path))?;
    let g = out.grid;
    for (k, pr) in out.pairs.iter().enumerate() {
        let mid = Scene::pair_mid(pr.ticks[0], pr.ticks[1]);
        let at = |r: usize, c: usize| pr.vectors.get(r * g.nx + c);
        for r in 0..g.ny {
            for c in 0..g.nx {
                let Some(v) = at(r, c) else { continue };
                let t = scene.truth_at(&[(v.x, v.y)], mid, dt)[0];
                let lap = |f: &dyn Fn(&Vector) -> f64| {
                    let mut l = 0.0;
                    let mut n = 0;
                    for (dr, dc) in [(0i64, 1i64), (0, -1), (1, 0), (-1, 0)] {
                        let (rr, cc) = (r as i64 + dr, c as i64 + dc);
                        if rr < 0 || cc < 0 || rr >= g.ny as i64 || cc >= g.nx as i64 {
                            continue;
                        }
                        if let Some(w) = at(rr as usize, cc as usize) {
                            if w.state.is_measured() {
                                l += f(w) - f(v);
                                n += 1;
                            }
                        }
                    }
                    if n > 0 {
                        l * 4.0 / n as f64
                    } else {
                        0.0
                    }
                };
                let (su, sv) = pr.sigma[r * g.nx + c];
                let sep = pr.separation.get(r * g.nx + c).copied().unwrap_or(0);
                writeln!(
                    f,
                    "{},{},{},{},{},{},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5},{},{:.3},{:.5},{:.5}",
                    fam.name,
                    seed,
                    k,
                    v.x,
                    v.y,
                    v.state.flag(),
                    v.u - t.2,
                    v.v - t.3,
                    su,
                    sv,
                    lap(&|w| w.u),
                    lap(&|w| w.v),
                    sep,
                    t.2.hypot(t.3),
                    v.u,
                    v.v
                )
                .map_err(spiv_formats::io_err(path))?;
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(seed: u64, glare: (f64, usize), other: (f64, usize)) -> FlowsRow {
        let s = Score {
            glare,
            other,
            all: glare.1 + other.1,
            ..Score::default()
        };
        s.row("f", seed, SPIV_FLOW, None, 1.0)
    }

    /// The worst member is chosen by the mean over every measured vector,
    /// not by either band's mean: seed 2's glare rows are worse than seed
    /// 3's, but seed 3 has far more badly measured vectors in all. A row
    /// that measured nothing is never the worst.
    #[test]
    fn the_worst_member_is_the_one_furthest_off_over_all_its_vectors() {
        let rows = [
            row(1, (1.0, 10), (1.0, 100)),
            row(2, (9.0, 3), (10.0, 100)),
            row(3, (4.0, 2), (60.0, 100)),
            row(4, (0.0, 0), (0.0, 0)),
        ];
        assert_eq!(rows[1].glare, Some(3.0));
        assert!(rows[3].measured.is_none());
        let refs: Vec<&FlowsRow> = rows.iter().collect();
        assert_eq!(worst(&refs).map(|r| r.seed), Some(3));
        assert_eq!(worst(&refs[..2]).map(|r| r.seed), Some(2));
        assert!(worst(&refs[3..]).is_none());
    }

    /// The spectral family's members span what the family promises, each
    /// seed its own, and the family's scene is the member's.
    #[test]
    fn spectral_members_span_their_ranges() {
        let ms: Vec<Member> = (1..=200).map(spectral_member).collect();
        let span = |f: &dyn Fn(&Member) -> f64| {
            ms.iter()
                .map(f)
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
                    (a.min(x), b.max(x))
                })
        };
        let within = |(lo, hi): (f64, f64), (a, b): (f64, f64)| {
            lo >= a && hi <= b && hi - lo > 0.8 * (b - a)
        };
        assert!(within(span(&|m| m.smallest_eddy), (4.0, 32.0)));
        assert!(within(span(&|m| m.rms_shift), (0.5, 8.0)));
        assert!(within(span(&|m| m.per_cell as f64), (6.0, 16.0)));
        assert!(within(span(&|m| m.particle_peak), (0.1, 0.4)));
        assert!(within(span(&|m| m.out_of_plane), (0.05, 0.25)));
        // Half the members at most 2 px rms (log-uniform from 0.5 to 8).
        let slow = ms.iter().filter(|m| m.rms_shift <= 2.0).count();
        assert!((70..130).contains(&slow), "{slow}");
        assert_ne!(spectral_member(1), spectral_member(2));
        let fam = families()
            .into_iter()
            .find(|f| f.scene == SceneKind::SpectralTurbulence)
            .unwrap();
        let p = fam.params(7);
        assert_eq!(p.flow_seed, 7);
        assert_eq!(p.rms_shift, Some(spectral_member(7).rms_shift));
        let sheet = p.sheet.unwrap();
        let travel = sheet.w_rms * f64::from(p.pair_dt) / sheet.thickness;
        assert!((travel - spectral_member(7).out_of_plane).abs() < 1e-12);
    }

    /// A valid vector is confidently wrong when it is off by more than 0.3
    /// px and by more than 3σ in either component: not when it is off by
    /// more than 3σ but within 0.3 px, nor when its σ covers it.
    #[test]
    fn confidently_wrong_needs_both_bounds() {
        let scene = Scene::new(SceneParams::new(SceneKind::Uniform), 1, 40);
        let dt = 13.0;
        let truth = scene.truth(&[(100.0, 100.0)], dt)[0];
        let vector = |du: f64| Vector {
            x: 100.0,
            y: 100.0,
            u: truth.2 + du,
            v: truth.3,
            state: State::Valid,
        };
        let mut s = Score::default();
        // off by 0.5 with σ 0.1: wrong; 0.2 with σ 0.01: within 0.3 px;
        // 0.5 with σ 0.2: within 3σ.
        let vs = [vector(0.5), vector(0.2), vector(0.5)];
        s.add(
            &scene,
            (0.0, dt),
            &vs,
            Some(&[(0.1, 0.1), (0.01, 0.01), (0.2, 0.2)]),
        );
        let r = s.row("uniform", 1, SPIV_FLOW, None, 1.0);
        assert_eq!(r.beyond_3sigma, Some(1.0 / 3.0));
    }
}

//! The flows the estimator works with: [`Velocity`], a velocity per pixel
//! (the host's steady field, its paths integrated through it), and
//! [`WarpFlow`], the node grid the core's warp follows
//! ([`spiv_core::warp::Flow`]: a velocity and an acceleration along the
//! path per node, in the core's fixed point and stored row order), made
//! from a field of node velocities or from a [`Velocity`].

use ndarray::Array2;
use spiv_core::buffers::FlowBuf;
use spiv_core::warp::Flow as CoreFlow;

use spiv_piv::{validate, Field};

/// A velocity per pixel, px per tick (u right, v down), upright.
#[derive(Debug, Clone)]
pub struct Velocity {
    /// Right.
    pub u: Array2<f32>,
    /// Down.
    pub v: Array2<f32>,
}

impl Velocity {
    /// No motion over an `h × w` image.
    pub fn zero(h: usize, w: usize) -> Velocity {
        Velocity {
            u: Array2::zeros((h, w)),
            v: Array2::zeros((h, w)),
        }
    }

    /// The velocity at `(x, y)` (px, pixel centres on integers), bilinear
    /// between pixels, the nearest edge pixel's outside.
    pub fn at(&self, x: f64, y: f64) -> (f64, f64) {
        let (h, w) = self.u.dim();
        if h == 0 || w == 0 {
            return (0.0, 0.0);
        }
        let xc = x.clamp(0.0, (w - 1) as f64);
        let yc = y.clamp(0.0, (h - 1) as f64);
        let (j, i) = (xc.floor() as usize, yc.floor() as usize);
        let (j1, i1) = ((j + 1).min(w - 1), (i + 1).min(h - 1));
        let (fx, fy) = (xc - j as f64, yc - i as f64);
        let lerp = |a: &Array2<f32>| {
            let top = f64::from(a[[i, j]]) * (1.0 - fx) + f64::from(a[[i, j1]]) * fx;
            let bot = f64::from(a[[i1, j]]) * (1.0 - fx) + f64::from(a[[i1, j1]]) * fx;
            top * (1.0 - fy) + bot * fy
        };
        (lerp(&self.u), lerp(&self.v))
    }

    /// Where a particle at `(x, y)` is after `ticks` ticks (either sign)
    /// in this steady field: midpoint steps of at most one tick.
    pub fn advect(&self, (mut x, mut y): (f64, f64), ticks: f64) -> (f64, f64) {
        let n = ticks.abs().ceil().max(1.0);
        let h = ticks / n;
        for _ in 0..n as usize {
            let (u1, v1) = self.at(x, y);
            let (u2, v2) = self.at(x + 0.5 * h * u1, y + 0.5 * h * v1);
            x += h * u2;
            y += h * v2;
        }
        (x, y)
    }

    /// The displacement over `ticks` ticks of the particle at `(x, y)`
    /// halfway through (its path from `−ticks/2` to `+ticks/2`).
    pub fn displacement(&self, (x, y): (f64, f64), ticks: f64) -> (f64, f64) {
        let a = self.advect((x, y), -0.5 * ticks);
        let b = self.advect((x, y), 0.5 * ticks);
        (b.0 - a.0, b.1 - a.1)
    }

    /// [`Velocity::displacement`] at every pixel: the field of
    /// displacements over `ticks` ticks, `(u, v)` in px.
    pub fn displacements(&self, ticks: f64) -> (Array2<f32>, Array2<f32>) {
        let mut u = Array2::zeros(self.u.dim());
        let mut v = Array2::zeros(self.u.dim());
        ndarray::Zip::indexed(&mut u)
            .and(&mut v)
            .par_for_each(|(i, j), u, v| {
                let (du, dv) = self.displacement((j as f64, i as f64), ticks);
                *u = du as f32;
                *v = dv as f32;
            });
        (u, v)
    }

    /// A displacement field over `ticks` ticks as a velocity.
    pub fn from_displacement(u: &Array2<f32>, v: &Array2<f32>, ticks: f64) -> Velocity {
        let k = (1.0 / ticks.max(1e-9)) as f32;
        Velocity {
            u: u.mapv(|x| x * k),
            v: v.mapv(|x| x * k),
        }
    }
}

/// A flow on a grid of nodes as the core's warp takes it
/// ([`spiv_core::warp::Flow`]), owned: node positions and spacing in
/// 1/16 px, velocities Q12 px/tick and accelerations along the path
/// `(v·∇)v` Q16 px/tick², all in the stored row order (y down the stored
/// rows).
#[derive(Debug, Clone, PartialEq)]
pub struct WarpFlow(FlowBuf);

impl WarpFlow {
    /// No motion.
    pub fn still() -> WarpFlow {
        WarpFlow(FlowBuf::still())
    }

    /// The core's flow `f`, owned.
    pub fn from_core(f: &CoreFlow<'_>) -> WarpFlow {
        WarpFlow(FlowBuf::of(f))
    }

    /// Whether this is [`WarpFlow::still`].
    pub fn is_still(&self) -> bool {
        self.0.is_still()
    }

    /// The core's view.
    pub fn view(&self) -> CoreFlow<'_> {
        self.0.view()
    }

    /// Node rows and columns, `(ny, nx)`.
    pub fn nodes(&self) -> (usize, usize) {
        (usize::from(self.0.ny), usize::from(self.0.nx))
    }

    /// Node `(r, c)` (stored order) as `((vx, vy), (ax, ay))` in the core's
    /// units.
    pub fn node(&self, r: usize, c: usize) -> ((i16, i16), (i16, i16)) {
        let f = &self.0;
        let k = r * usize::from(f.nx) + c;
        ((f.vx[k], f.vy[k]), (f.ax[k], f.ay[k]))
    }

    /// The layout `(x0, y0, pitch)`, 1/16 px.
    pub fn layout(&self) -> (i32, i32, u16) {
        (self.0.x0, self.0.y0, self.0.pitch)
    }

    /// The flow whose nodes hold the upright velocities `u`, `v` (px per
    /// tick, `ny × nx`), node `(0, 0)` at upright `first` (x, y px), nodes
    /// `pitch` px apart (a whole number of 1/16 px, at most 256 px), over
    /// an image `h` rows high whose rows are stored bottom-up when `flip`.
    /// Accelerations are `(v·∇)v` from central differences between nodes
    /// (one-sided at the edges). Values beyond the core's range saturate;
    /// a non-finite value counts as 0.
    pub fn from_nodes(
        first: (f64, f64),
        pitch: f64,
        u: &Array2<f64>,
        v: &Array2<f64>,
        h: usize,
        flip: bool,
    ) -> WarpFlow {
        let (ny, nx) = u.dim();
        if nx == 0 || ny == 0 || nx > usize::from(u16::MAX) || ny > usize::from(u16::MAX) {
            return WarpFlow::still();
        }
        let fin = |x: f64| if x.is_finite() { x } else { 0.0 };
        let d = |f: &Array2<f64>, r: usize, c: usize, along_x: bool| -> f64 {
            let n = if along_x { nx } else { ny };
            let i = if along_x { c } else { r };
            if n < 2 {
                return 0.0;
            }
            let (lo, hi) = (i.saturating_sub(1), (i + 1).min(n - 1));
            let at = |k: usize| {
                if along_x {
                    fin(f[[r, k]])
                } else {
                    fin(f[[k, c]])
                }
            };
            (at(hi) - at(lo)) / ((hi - lo) as f64 * pitch)
        };
        let q = |x: f64, k: f64| (fin(x) * k).round().clamp(-32768.0, 32767.0) as i16;
        let n = nx * ny;
        let (mut vx, mut vy, mut ax, mut ay) = (vec![0; n], vec![0; n], vec![0; n], vec![0; n]);
        for r in 0..ny {
            for c in 0..nx {
                let (uu, vv) = (fin(u[[r, c]]), fin(v[[r, c]]));
                let a_x = uu * d(u, r, c, true) + vv * d(u, r, c, false);
                let a_y = uu * d(v, r, c, true) + vv * d(v, r, c, false);
                // Stored order: rows reversed and y negated when flipped.
                let (sr, sgn) = if flip { (ny - 1 - r, -1.0) } else { (r, 1.0) };
                let k = sr * nx + c;
                vx[k] = q(uu, 4096.0);
                vy[k] = q(sgn * vv, 4096.0);
                ax[k] = q(a_x, 65536.0);
                ay[k] = q(sgn * a_y, 65536.0);
            }
        }
        let q4 = |x: f64| (x * 16.0).round() as i32;
        let last_y = first.1 + (ny - 1) as f64 * pitch;
        let y0 = if flip {
            (h as f64 - 1.0) - last_y
        } else {
            first.1
        };
        WarpFlow(FlowBuf {
            nx: nx as u16,
            ny: ny as u16,
            x0: q4(first.0),
            y0: q4(y0),
            pitch: q4(pitch).clamp(16, i32::from(spiv_core::warp::MAX_PITCH)) as u16,
            vx,
            vy,
            ax,
            ay,
        })
    }

    /// The flow of a field of node velocities (px per tick): its holes
    /// filled from their neighbours ([`validate::extended`]), on its grid.
    pub fn from_field(f: &Field, h: usize, flip: bool) -> WarpFlow {
        let (u, v) = validate::extended(&f.u, &f.v, &f.state);
        let first = f.grid.centre(0, 0);
        WarpFlow::from_nodes(first, f.grid.step as f64, &u, &v, h, flip)
    }

    /// The flow of a velocity per pixel, sampled every `pitch` px from
    /// pixel (0, 0).
    pub fn from_velocity(vel: &Velocity, pitch: usize, flip: bool) -> WarpFlow {
        let (h, w) = vel.u.dim();
        let pitch = pitch.max(1);
        if h == 0 || w == 0 {
            return WarpFlow::still();
        }
        let (ny, nx) = ((h - 1) / pitch + 1, (w - 1) / pitch + 1);
        let at = |f: &Array2<f32>, r: usize, c: usize| f64::from(f[[r * pitch, c * pitch]]);
        let u = Array2::from_shape_fn((ny, nx), |(r, c)| at(&vel.u, r, c));
        let v = Array2::from_shape_fn((ny, nx), |(r, c)| at(&vel.v, r, c));
        WarpFlow::from_nodes((0.0, 0.0), pitch as f64, &u, &v, h, flip)
    }
}

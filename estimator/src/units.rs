//! Units as types at the estimator's boundary. The PIV engine's
//! [`Field`] holds displacements between its two frames; here a field
//! says what it is: velocities in px per tick ([`PerTick`]: the flow a
//! pair's rung frames follow, the climb's estimate) or displacements over
//! a pair of `dt` ticks in px per pair ([`PerPair`]: what the ladder
//! reports). Conversions between them are the methods below and nothing
//! else.

use std::ops::{Deref, DerefMut};

use spiv_piv::Field;

/// A span of time, ticks (one spike plane each): a pair's separation.
#[derive(Debug, Clone, Copy, PartialEq, PartialOrd)]
pub struct Ticks(pub f64);

/// A field of velocities, px per tick (uncertainties likewise).
#[derive(Debug, Clone)]
pub struct PerTick(pub Field);

/// A field of displacements over a pair of `dt` ticks, px per pair
/// (uncertainties likewise).
#[derive(Debug, Clone)]
pub struct PerPair {
    field: Field,
    dt: Ticks,
}

/// `f` with displacements and uncertainties times `k`.
fn scaled(f: &Field, k: f64) -> Field {
    let mut o = f.clone();
    o.u.mapv_inplace(|x| x * k);
    o.v.mapv_inplace(|x| x * k);
    o.sigma.mapv_inplace(|(a, b)| (a * k, b * k));
    o
}

impl PerTick {
    /// The velocities a field of displacements over `s` ticks measured:
    /// each divided by `s` (at least 10⁻⁹).
    ///
    /// ```
    /// use spiv_estimator::units::{PerTick, Ticks};
    /// use spiv_piv::{Field, Grid};
    /// let mut f = Field::unmeasured(Grid::new(64, 64, 32, 16).unwrap());
    /// f.u.fill(8.0);
    /// let v = PerTick::from_displacements(&f, Ticks(4.0));
    /// assert_eq!(v.u[[0, 0]], 2.0);
    /// assert_eq!(v.over(Ticks(13.0)).u[[0, 0]], 26.0);
    /// ```
    pub fn from_displacements(f: &Field, s: Ticks) -> PerTick {
        PerTick(scaled(f, 1.0 / s.0.max(1e-9)))
    }

    /// The displacements over a pair of `dt` ticks.
    pub fn over(&self, dt: Ticks) -> PerPair {
        PerPair {
            field: scaled(&self.0, dt.0),
            dt,
        }
    }
}

impl PerPair {
    /// `field` as displacements over `dt` ticks.
    pub fn new(field: Field, dt: Ticks) -> PerPair {
        PerPair { field, dt }
    }

    /// The pair's separation.
    pub fn dt(&self) -> Ticks {
        self.dt
    }

    /// The velocities, px per tick.
    pub fn per_tick(&self) -> PerTick {
        PerTick::from_displacements(&self.field, self.dt)
    }

    /// The same motion as displacements over `to` ticks.
    ///
    /// ```
    /// use spiv_estimator::units::{PerPair, Ticks};
    /// use spiv_piv::{Field, Grid};
    /// let mut f = Field::unmeasured(Grid::new(64, 64, 32, 16).unwrap());
    /// f.v.fill(3.0);
    /// let p = PerPair::new(f, Ticks(12.0));
    /// assert_eq!(p.over(Ticks(4.0)).v[[0, 0]], 1.0);
    /// assert_eq!(p.per_tick().v[[0, 0]], 0.25);
    /// ```
    pub fn over(&self, to: Ticks) -> PerPair {
        PerPair {
            field: scaled(&self.field, to.0 / self.dt.0),
            dt: to,
        }
    }

    /// The field, px per pair.
    pub fn into_field(self) -> Field {
        self.field
    }
}

impl Deref for PerTick {
    type Target = Field;
    fn deref(&self) -> &Field {
        &self.0
    }
}

impl DerefMut for PerTick {
    fn deref_mut(&mut self) -> &mut Field {
        &mut self.0
    }
}

impl Deref for PerPair {
    type Target = Field;
    fn deref(&self) -> &Field {
        &self.field
    }
}

impl DerefMut for PerPair {
    fn deref_mut(&mut self) -> &mut Field {
        &mut self.field
    }
}

//! Physical units: a recording's calibration (pixel size on the object,
//! tick rate) turns displacements in px per pair into velocities in m/s.

use crate::Error;

/// Largest pixel size accepted, mm (a 1 m pixel is no camera).
pub const MAX_PIXEL_MM: f64 = 1000.0;
/// Largest tick rate accepted, Hz (spike cameras run at 20–40 kHz).
pub const MAX_TICK_HZ: f64 = 1e9;

/// A recording's calibration.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Calibration {
    /// Size of a pixel on the object, mm.
    pub pixel_mm: f64,
    /// Ticks per second, Hz.
    pub tick_hz: f64,
}

impl Calibration {
    /// A calibration of `pixel_mm` mm per pixel and `tick_hz` ticks per
    /// second, each finite, above 0 and within [`MAX_PIXEL_MM`],
    /// [`MAX_TICK_HZ`].
    pub fn new(pixel_mm: f64, tick_hz: f64) -> Result<Calibration, Error> {
        if !(pixel_mm > 0.0 && pixel_mm <= MAX_PIXEL_MM) {
            return Err(Error::PixelSize(pixel_mm));
        }
        if !(tick_hz > 0.0 && tick_hz <= MAX_TICK_HZ) {
            return Err(Error::TickRate(tick_hz));
        }
        Ok(Calibration { pixel_mm, tick_hz })
    }

    /// The calibration a run uses: each of the command line's values where
    /// given, else the recording's metadata; `None` when neither is
    /// known, and an error naming the missing half when only one is.
    pub fn resolve(
        pixel_mm: Option<f64>,
        tick_hz: Option<f64>,
        meta: Option<Calibration>,
    ) -> Result<Option<Calibration>, Error> {
        let px = pixel_mm.or(meta.map(|m| m.pixel_mm));
        let hz = tick_hz.or(meta.map(|m| m.tick_hz));
        match (px, hz) {
            (Some(p), Some(h)) => Calibration::new(p, h).map(Some),
            (Some(p), None) => {
                Calibration::new(p, 1.0)?;
                Err(Error::Half("the tick rate (Hz)"))
            }
            (None, Some(h)) => {
                Calibration::new(1.0, h)?;
                Err(Error::Half("the pixel size (mm)"))
            }
            (None, None) => Ok(None),
        }
    }

    /// A displacement of `px` pixels over `ticks` ticks as a velocity, m/s.
    pub fn m_per_s(&self, px: f64, ticks: f64) -> f64 {
        px * self.pixel_mm * 1e-3 * self.tick_hz / ticks
    }

    /// `ticks` ticks in seconds.
    pub fn seconds(&self, ticks: f64) -> f64 {
        ticks / self.tick_hz
    }

    /// `px` pixels in metres.
    pub fn metres(&self, px: f64) -> f64 {
        px * self.pixel_mm * 1e-3
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 13 px over 13 ticks at 20 kHz with 0.02 mm pixels is 1 px/tick =
    /// 0.4 m/s; the command line wins over metadata, and half a
    /// calibration is refused, naming the missing half.
    #[test]
    fn velocities_and_resolution() {
        let c = Calibration::new(0.02, 20_000.0).unwrap();
        assert!((c.m_per_s(13.0, 13.0) - 0.4).abs() < 1e-12);
        assert!((c.seconds(20_000.0) - 1.0).abs() < 1e-12);
        let meta = Some(c);
        let r = Calibration::resolve(Some(0.05), None, meta)
            .unwrap()
            .unwrap();
        assert_eq!((r.pixel_mm, r.tick_hz), (0.05, 20_000.0));
        assert!(matches!(
            Calibration::resolve(Some(0.05), None, None),
            Err(Error::Half("the tick rate (Hz)"))
        ));
        let e = Calibration::resolve(None, Some(20_000.0), None).unwrap_err();
        assert!(
            e.to_string().contains("the pixel size (mm) is missing"),
            "{e}"
        );
        assert!(matches!(Calibration::resolve(None, None, None), Ok(None)));
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY, 2e3] {
            assert!(Calibration::new(bad, 1.0).is_err(), "{bad}");
            assert!(
                Calibration::resolve(Some(bad), None, None).is_err(),
                "{bad}"
            );
        }
        assert!(Calibration::new(1.0, 0.0).is_err());
    }
}

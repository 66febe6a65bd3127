//! `spiv simulate`: one scene through both cameras, written as the files of
//! docs/formats.md — `spikes.dat`, `scene.json`, `frame_a.png`, `frame_b.png`,
//! `truth.csv`, `profile.csv`.
//!
//! Only the ticks the requested frames need are generated: a pair (k_a, k_b)
//! with ⌊n_max/2⌋ = 64 ticks of spikes on each side (141 planes by default),
//! streamed to disk one plane at a time.

use std::path::Path;

use crate::meta::{Glare, SceneInfo, SceneMeta};
use crate::scene::{Scene, SceneParams, PIXEL_MM, TICK_HZ};
use crate::sensor::{FrameCamera, FrameCameraParams, SensorParams, SpikeSensor};
use spiv_formats::capture::Capture;
use spiv_formats::dat::{plane_bytes, DatWriter};
use spiv_formats::dense::write_dense;
use spiv_formats::grid::Grid;
use spiv_formats::image::write_levels;
use spiv_formats::vectors::{write_profile, write_vectors};
use spiv_formats::FormatError;

use crate::Error;

/// What to simulate.
#[derive(Debug, Clone)]
pub struct Request {
    /// The scene.
    pub scene: SceneParams,
    /// Seed of particles, sensor and camera noise.
    pub seed: u64,
    /// Planes to write (`None`: the pair plus `margin` on each side).
    pub ticks: Option<u32>,
    /// Ticks of spikes kept before the first and after the second frame
    /// (⌊n_max/2⌋ = 64 for the default adaptive reconstruction).
    pub margin: u32,
    /// Spike sensor.
    pub sensor: SensorParams,
    /// Frame camera.
    pub camera: FrameCameraParams,
}

impl Request {
    /// The defaults for a scene.
    pub fn new(scene: SceneParams, seed: u64) -> Request {
        Request {
            scene,
            seed,
            ticks: None,
            margin: 64,
            sensor: SensorParams::default(),
            camera: FrameCameraParams::default(),
        }
    }

    /// Planes written and the pair in file ticks.
    pub fn layout(&self) -> Result<(u32, [u32; 2]), Error> {
        let dt = self.scene.pair_dt;
        match self.ticks {
            None => Ok((dt + 2 * self.margin + 1, [self.margin, self.margin + dt])),
            Some(n) if n > dt => {
                let ka = (n - 1 - dt) / 2;
                Ok((n, [ka, ka + dt]))
            }
            Some(n) => Err(Error::Format(FormatError::Parse {
                path: "--ticks".into(),
                msg: format!("{n} ticks cannot hold a pair {dt} ticks apart"),
            })),
        }
    }
}

/// Everything `spiv simulate` made, in memory as well.
#[derive(Debug, Clone)]
pub struct Simulated {
    /// The metadata written to `scene.json`.
    pub meta: SceneMeta,
    /// The seeded scene.
    pub scene: Scene,
    /// Frame camera frames at k_a and k_b, digital numbers, upright.
    pub frames: [Vec<u16>; 2],
    /// Spikes written.
    pub spikes: u64,
}

/// Runs `req`: the spike planes go to `sink` one at a time (stored row
/// order, bottom-up, as in a `.dat`), the frame camera's pair and the truth
/// come back in memory. `progress` is called with (planes done, planes in
/// all).
pub fn simulate(
    req: &Request,
    mut progress: impl FnMut(u32, u32),
    mut sink: impl FnMut(&[u8]) -> Result<(), FormatError>,
) -> Result<Simulated, Error> {
    let p = &req.scene;
    let pb = plane_bytes(p.width, p.height)?;
    let (ticks, pair) = req.layout()?;
    let scene = Scene::new(p.clone(), req.seed, ticks);
    let (w, h) = (p.width, p.height);
    let mut sensor = SpikeSensor::new(req.sensor, w, h, req.seed ^ 0x5eed_5e45);
    let mut light = vec![0f32; usize::from(w) * usize::from(h)];
    let mut plane = vec![0u8; pb];
    let mut spikes = 0u64;
    for t in 0..ticks {
        scene.render(f64::from(t) + 0.5, &mut light);
        spikes += sensor.tick(&light, true, &mut plane);
        sink(&plane)?;
        progress(t + 1, ticks);
    }
    let camera = FrameCamera { params: req.camera };
    let frames = [
        camera.capture(&scene, pair[0], req.seed),
        camera.capture(&scene, pair[1], req.seed.wrapping_add(1)),
    ];
    let meta = SceneMeta {
        capture: Capture {
            width: w,
            height: h,
            tick_hz: TICK_HZ,
            pixel_mm: PIXEL_MM,
            flip: true,
            first_tick: 0,
            planes: u64::from(ticks),
            pair,
        },
        scene: SceneInfo {
            name: p.kind.name().to_string(),
            params: p.clone(),
            sensor: req.sensor,
            frame_camera: req.camera,
            density_reached: scene.density_reached,
        },
        seed: req.seed,
        glare: Glare {
            peak: p.glare_peak,
            sigma_px: p.glare_sigma,
        },
        version: env!("CARGO_PKG_VERSION").to_string(),
    };
    Ok(Simulated {
        meta,
        scene,
        frames,
        spikes,
    })
}

/// The frame camera's digital numbers as the image file holds them: 8-bit
/// as is, deeper ADCs spread over 16 bits.
pub fn write_frame(path: &Path, req: &Request, w: u16, h: u16, f: &[u16]) -> Result<(), Error> {
    if req.camera.bits <= 8 {
        Ok(write_levels(path, u32::from(w), u32::from(h), f, 255)?)
    } else {
        let max = u32::from(req.camera.max_dn()).max(1);
        let v: Vec<u16> = f
            .iter()
            .map(|&d| ((u32::from(d) * 65535 + max / 2) / max) as u16)
            .collect();
        Ok(write_levels(
            path,
            u32::from(w),
            u32::from(h),
            &v,
            u16::MAX,
        )?)
    }
}

/// [`simulate`] with the spike planes kept in memory, back to back (stored
/// row order): for runs that use the stream more than once.
pub fn simulate_planes(req: &Request) -> Result<(Vec<u8>, Simulated), Error> {
    let mut planes = Vec::new();
    let sim = simulate(
        req,
        |_, _| {},
        |plane| {
            planes.extend_from_slice(plane);
            Ok(())
        },
    )?;
    Ok((planes, sim))
}

/// Runs `req` and writes its files into `dir` (created if missing).
/// `progress` is called with (planes done, planes in all).
pub fn simulate_to_dir(
    req: &Request,
    dir: &Path,
    progress: impl FnMut(u32, u32),
) -> Result<Simulated, Error> {
    std::fs::create_dir_all(dir).map_err(spiv_formats::io_err(dir))?;
    let (w, h) = (req.scene.width, req.scene.height);
    let mut writer = DatWriter::create(&dir.join("spikes.dat"), w, h)?;
    let sim = simulate(req, progress, |plane| writer.write_planes(plane))?;
    writer.finish()?;
    for (name, f) in ["frame_a.png", "frame_b.png"].iter().zip(&sim.frames) {
        write_frame(&dir.join(name), req, w, h, f)?;
    }
    let pair = sim.meta.capture.pair;
    let dt = f64::from(pair[1] - pair[0]);
    let mid = Scene::pair_mid(u64::from(pair[0]), u64::from(pair[1]));
    let truth = sim.scene.truth_vectors_at(
        &Grid::new(usize::from(w), usize::from(h), 32, 16)
            .map(|g| g.centres())
            .unwrap_or_default(),
        mid,
        dt,
    );
    write_vectors(&dir.join("truth.csv"), &truth)?;
    write_dense(&dir.join("truth.flo"), &sim.scene.truth_dense_at(mid, dt))?;
    write_profile(&dir.join("profile.csv"), &sim.scene.profile(dt))?;
    sim.meta.write(&dir.join("scene.json"))?;
    Ok(sim)
}

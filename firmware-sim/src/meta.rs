//! `scene.json` of a simulated recording (docs/formats.md): the layout
//! ([`spiv_formats::capture::Capture`]) and the scene, sensor and camera
//! that made it.

use std::path::Path;

use serde::{Deserialize, Serialize};
use spiv_formats::capture::{read_json, write_json, Capture};

use crate::Error;

use crate::scene::SceneParams;
use crate::sensor::{FrameCameraParams, SensorParams};

/// The glare band.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Glare {
    /// Peak light I0, thresholds/tick.
    pub peak: f64,
    /// Width σ, px.
    pub sigma_px: f64,
}

/// The whole `scene.json` of a simulated `.dat`: the layout every reader
/// needs ([`Capture`], flattened: its fields come first) and how the scene
/// was made.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneMeta {
    /// Size, row order, clock, pair.
    #[serde(flatten)]
    pub capture: Capture,
    /// The scene and every parameter.
    pub scene: SceneInfo,
    /// Seed.
    pub seed: u64,
    /// The glare band.
    pub glare: Glare,
    /// spiv version that wrote it.
    pub version: String,
}

/// The scene part of `scene.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneInfo {
    /// Scene name.
    pub name: String,
    /// Scene parameters.
    pub params: SceneParams,
    /// Spike sensor parameters.
    pub sensor: SensorParams,
    /// Frame camera parameters.
    pub frame_camera: FrameCameraParams,
    /// 32×32 cells that reached the seeding density, of all.
    pub density_reached: (usize, usize),
}

impl SceneMeta {
    /// Writes it as pretty JSON.
    pub fn write(&self, path: &Path) -> Result<(), Error> {
        Ok(write_json(path, self)?)
    }

    /// Reads one.
    pub fn read(path: &Path) -> Result<SceneMeta, Error> {
        Ok(read_json(path)?)
    }
}

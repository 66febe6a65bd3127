//! `scene.json`, written beside every `.dat` spiv writes (FORMATS.md).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::{io_err, FormatError};
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

/// The scene metadata of a `.dat` written by spiv.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneMeta {
    /// Width, px.
    pub width: u16,
    /// Height, px.
    pub height: u16,
    /// Ticks per second.
    pub tick_hz: f64,
    /// Pixel size, mm.
    pub pixel_mm: f64,
    /// Stored rows bottom-up (the camera's layout).
    pub flip: bool,
    /// Scene tick of the file's plane 0.
    pub first_tick: u32,
    /// Planes in the file.
    pub planes: u64,
    /// The pair [k_a, k_b] in file ticks.
    pub pair: [u32; 2],
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

/// `scene.json` beside `dat`.
pub fn path_beside(dat: &Path) -> PathBuf {
    dat.with_file_name("scene.json")
}

impl SceneMeta {
    /// Writes it as pretty JSON.
    pub fn write(&self, path: &Path) -> Result<(), FormatError> {
        let text = serde_json::to_string_pretty(self).map_err(|e| FormatError::Parse {
            path: path.to_path_buf(),
            msg: e.to_string(),
        })?;
        std::fs::write(path, text).map_err(io_err(path))
    }

    /// Reads one.
    pub fn read(path: &Path) -> Result<SceneMeta, FormatError> {
        let text = std::fs::read_to_string(path).map_err(io_err(path))?;
        serde_json::from_str(&text).map_err(|e| FormatError::Parse {
            path: path.to_path_buf(),
            msg: e.to_string(),
        })
    }

    /// The `scene.json` beside a `.dat`, if there is one (an unreadable one is an error).
    pub fn beside(dat: &Path) -> Result<Option<SceneMeta>, FormatError> {
        let p = path_beside(dat);
        if p.exists() {
            Self::read(&p).map(Some)
        } else {
            Ok(None)
        }
    }
}

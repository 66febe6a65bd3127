//! The layout half of `scene.json` (docs/formats.md), written beside every `.dat`
//! spiv writes: what a reader needs to take the planes apart — size, row
//! order, clock, pixel size, the pair — and nothing about how the scene was
//! made (the simulator adds that, `spiv_firmware_sim::meta`). Unknown fields
//! are ignored, so any `scene.json` spiv wrote reads here.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::{io_err, FormatError};

/// How a recording's planes are laid out and clocked.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Capture {
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
}

/// `scene.json` beside `dat`.
pub fn path_beside(dat: &Path) -> PathBuf {
    dat.with_file_name("scene.json")
}

/// Reads a JSON file into `T`.
pub fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T, FormatError> {
    let text = std::fs::read_to_string(path).map_err(io_err(path))?;
    serde_json::from_str(&text).map_err(|e| FormatError::Parse {
        path: path.to_path_buf(),
        msg: e.to_string(),
    })
}

/// Writes `value` as pretty JSON.
pub fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<(), FormatError> {
    let text = serde_json::to_string_pretty(value).map_err(|e| FormatError::Parse {
        path: path.to_path_buf(),
        msg: e.to_string(),
    })?;
    std::fs::write(path, text).map_err(io_err(path))
}

impl Capture {
    /// Reads the layout from a `scene.json`.
    pub fn read(path: &Path) -> Result<Capture, FormatError> {
        read_json(path)
    }

    /// The layout in the `scene.json` beside a `.dat`, if there is one (an
    /// unreadable one is an error).
    pub fn beside(dat: &Path) -> Result<Option<Capture>, FormatError> {
        let p = path_beside(dat);
        if p.exists() {
            Self::read(&p).map(Some)
        } else {
            Ok(None)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_the_layout_of_a_full_scene_json() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("scene.json");
        std::fs::write(
            &p,
            r#"{"width": 64, "height": 32, "tick_hz": 20000.0, "pixel_mm": 0.02,
                "flip": true, "first_tick": 0, "planes": 100, "pair": [40, 53],
                "scene": {"name": "whatever"}, "seed": 3}"#,
        )
        .unwrap();
        let c = Capture::beside(&dir.path().join("spikes.dat"))
            .unwrap()
            .unwrap();
        assert_eq!(
            (c.width, c.height, c.pair, c.flip),
            (64, 32, [40, 53], true)
        );
        std::fs::write(&p, "{").unwrap();
        assert!(matches!(Capture::read(&p), Err(FormatError::Parse { .. })));
        assert!(Capture::beside(&dir.path().join("none/x.dat"))
            .unwrap()
            .is_none());
    }
}

//! The Cortex-M4 firmware's input through the native firmware loop: the
//! parity line `spiv-firmware-sim --checksum` prints must be the one
//! committed in `cortex-m4/expected.txt`, which the firmware under QEMU must
//! print too (`firmware-sim/cost.sh`, run by `.ci/run`). A change of the
//! core's output shows here first; a platform difference shows there.

use std::ffi::OsString;
use std::process::Command;

/// The parity line of `spiv-firmware-sim --pairs 1 --checksum ARGS`.
fn checksum_line(args: &[OsString]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_spiv-firmware-sim"))
        .args(["--pairs", "1", "--checksum"])
        .args(args)
        .output()
        .expect("run spiv-firmware-sim");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).trim().to_string()
}

#[test]
fn native_loop_prints_the_committed_parity_line() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("cortex-m4");
    let line = checksum_line(&["--input".into(), dir.join("data/strip.dat").into()]);
    let want = std::fs::read_to_string(dir.join("expected.txt")).expect("expected.txt");
    assert_eq!(line, want.trim());
}

/// The control message the Cortex-M4 firmware's motion-compensated run
/// hears (`cortex-m4/data/control.bin`): the strip scene's true velocity of
/// every stored row in each of two 64-px tile columns, at the column's
/// centre (the prediction a perfect host would send; a 2-D grid, so the
/// firmware's cost is the grid's), applying from pair 0. Rebuilt here from
/// `scene.json`; `SPIV_BLESS=1` rewrites the committed file.
fn strip_control(dir: &std::path::Path) -> Vec<u8> {
    let text = std::fs::read_to_string(dir.join("data/scene.json")).expect("scene.json");
    let json: serde_json::Value = serde_json::from_str(&text).expect("scene.json is JSON");
    let params: spiv_firmware_sim::scene::SceneParams =
        serde_json::from_value(json["scene"]["params"].clone()).expect("scene params");
    let pair = &json["pair"];
    let dt = (pair[1].as_f64().expect("pair") - pair[0].as_f64().expect("pair")).max(1.0);
    let flip = json["flip"].as_bool().expect("flip");
    let (w, h) = (params.width, params.height);
    let flow = params.flow();
    let q = |px_per_tick: f64| (px_per_tick * f64::from(spiv_core::motion::Q)).round() as i16;
    let (tile, cols) = (64u16, w.div_ceil(64));
    let (mut vx, mut vy) = (Vec::new(), Vec::new());
    for r in 0..h {
        let upright = if flip { h - 1 - r } else { r };
        for c in 0..cols {
            let x = (f64::from(c) + 0.5) * f64::from(tile);
            let (u, v) = flow.displacement(x, f64::from(upright) + 0.5, dt);
            vx.push(q(u / dt));
            vy.push(q(if flip { -v } else { v } / dt));
        }
    }
    spiv_firmware_sim::firmware::Control {
        motion: (vx, vy),
        cols,
        tile,
        ..Default::default()
    }
    .message(0, 0, w, h)
    .expect("control message")
}

#[test]
fn committed_control_is_the_strips_true_motion() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("cortex-m4");
    let want = strip_control(&dir);
    let path = dir.join("data/control.bin");
    if std::env::var_os("SPIV_BLESS").is_some() {
        std::fs::write(&path, &want).expect("write control.bin");
    }
    let got = std::fs::read(&path).expect("control.bin");
    assert_eq!(
        got, want,
        "cortex-m4/data/control.bin (SPIV_BLESS=1 rewrites it)"
    );
}

/// The motion-compensated run: the same strip, `--method mc`, hearing the
/// committed control before the first plane, as the firmware does; its
/// line is `cortex-m4/expected-mc.txt`.
#[test]
fn native_mc_loop_prints_the_committed_parity_line() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("cortex-m4");
    let run = |bootstrap: &str| {
        checksum_line(&[
            "--method".into(),
            "mc".into(),
            "--bootstrap".into(),
            bootstrap.into(),
            "--control".into(),
            dir.join("data/control.bin").into(),
            "--input".into(),
            dir.join("data/strip.dat").into(),
        ])
    };
    let line = run("tfp");
    // The control applied from the first frame: how frames are made before
    // a motion arrives never mattered.
    assert_eq!(line, run("adaptive"));
    let path = dir.join("expected-mc.txt");
    if std::env::var_os("SPIV_BLESS").is_some() {
        std::fs::write(&path, format!("{line}\n")).expect("write expected-mc.txt");
    }
    let want = std::fs::read_to_string(path).expect("expected-mc.txt");
    assert_eq!(line, want.trim());
    // The motion took effect: the frames differ from the adaptive run's.
    let plain = std::fs::read_to_string(dir.join("expected.txt")).expect("expected.txt");
    assert_ne!(line, plain.trim());
}

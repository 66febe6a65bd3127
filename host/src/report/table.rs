//! The tables a run prints: the paper's comparison (Tables 1–2 layout) and
//! the wire line.

use std::fmt::Write as _;

use crate::metrics::rmae_ratio;
use crate::pipeline::{FrameKind, Job, Outcome};

/// The table name of a kind of frames (`tfp`: the TFP window, ticks).
pub fn label(s: FrameKind, tfp: u16) -> String {
    match s {
        FrameKind::Frame => "frame camera".into(),
        FrameKind::Tfp => format!("spike, TFP n={tfp}"),
        FrameKind::Adaptive => "spike, adaptive".into(),
        FrameKind::Mc => "spike, motion-comp.".into(),
        FrameKind::McWide => "spike, m.-c. wide".into(),
    }
}

/// The paper's Tables 1–2 layout for one run, as printed by `spiv run`.
pub fn run_table(o: &Outcome, job: &Job) -> String {
    let mut s = String::new();
    let m = &o.sim.meta;
    let dt = f64::from(m.capture.pair[1] - m.capture.pair[0]);
    // Pixel size and tick rate from the capture's metadata.
    let tick_hz = m.capture.tick_hz;
    let to_ms = m.capture.pixel_mm / 1000.0 / (dt / tick_hz);
    let g = &o.measured[0].glare;
    let r = &o.measured[0].rest;
    let _ = writeln!(
        s,
        "{} seed {}: {}x{} px, pair at ticks {:?} ({} ticks = {:.2} ms apart), truth max {:.2} px/pair",
        m.scene.name,
        m.seed,
        m.capture.width,
        m.capture.height,
        m.capture.pair,
        dt,
        dt / tick_hz * 1e3,
        o.truth.iter().map(|v| v.u.abs()).fold(0.0, f64::max)
    );
    let _ = writeln!(
        s,
        "{:<20} | {:^29} | {:^29}",
        "",
        format!("glare rows (y < {:.0} px, {} rows)", o.glare_limit, g.rows),
        format!("other rows ({} rows)", r.rows)
    );
    let _ = writeln!(
        s,
        "{:<20} | {:>6} {:>7} {:>8} {:>5} | {:>6} {:>7} {:>8} {:>5}",
        "frames", "RMAE", "RMSE px", "RMSE m/s", "lost", "RMAE", "RMSE px", "RMSE m/s", "lost"
    );
    for x in &o.measured {
        let _ = writeln!(
            s,
            "{:<20} | {:>6.3} {:>7.3} {:>8.4} {:>5} | {:>6.3} {:>7.3} {:>8.4} {:>5}",
            label(x.source, job.tfp_window),
            x.glare.rmae,
            x.glare.rmse,
            x.glare.rmse * to_ms,
            x.glare.lost,
            x.rest.rmae,
            x.rest.rmse,
            x.rest.rmse * to_ms,
            x.rest.lost,
        );
    }
    let f = &o.measured[0];
    for x in &o.measured[1..] {
        let _ = writeln!(
            s,
            "{:<20} | {:>6.3} {:>22} | {:>6.3}",
            format!("frame / {}", x.source.name()),
            rmae_ratio(f.glare.rmae, x.glare.rmae),
            "",
            rmae_ratio(f.rest.rmae, x.rest.rmae)
        );
    }
    s
}

/// The wire line under the table: pair sizes against raw spikes, loss and
/// bit-exactness.
pub fn wire_line(o: &Outcome, job: &Job) -> String {
    format!(
        "wire ({:?}): adaptive pair {} B, TFP pair {} B, motion-comp. pair {} B (wide pair {} B), raw spikes {} B per pair period ({:.1}x less); lost {}, bit-exact {}",
        job.encoding,
        o.link.adaptive_bytes,
        o.link.tfp_bytes,
        o.link.mc_bytes,
        o.link.wide_bytes,
        o.link.raw_bytes_per_period,
        o.link.raw_bytes_per_period as f64 / o.link.adaptive_bytes.max(1) as f64,
        o.link.lost_frames,
        if o.link.bit_exact { "yes" } else { "NO" },
    )
}

//! Drivers: the simulated firmware run on a streamed scene or a `.dat`
//! file, plane by plane, hearing the host's control messages between
//! planes when given a downlink.

use crate::downlink::ControlStream;
use crate::firmware::{Config, Firmware, Link};
use crate::ladder::{LadderConfig, LadderFirmware};
use crate::Error;

/// Runs the firmware on a simulated scene, the planes streamed straight
/// from the sensor into the loop (never stored). `req.ticks` is set from
/// the schedule when `cfg.schedule.pairs` is given. Returns the firmware (its
/// counters, link and kept frames) and the simulation (truth, frame camera).
/// With a `downlink`, the firmware hears the host between planes.
pub fn run_on_scene<L: Link>(
    req: &crate::simulation::Request,
    cfg: Config,
    link: L,
    keep: bool,
    mut downlink: Option<&mut ControlStream>,
    progress: impl FnMut(u32, u32),
) -> Result<(Firmware<L>, crate::simulation::Simulated), Error> {
    let mut req = req.clone();
    if let Some(p) = cfg.schedule.pairs {
        req.ticks = Some(cfg.ticks_for(p).max(req.scene.pair_dt + 1));
    }
    let mut fw = Firmware::new(req.scene.width, req.scene.height, cfg, link)?;
    if keep {
        fw.keep = Some(Vec::new());
    }
    let mut failed: Option<Error> = None;
    let sim = crate::simulation::simulate(&req, progress, |plane| {
        if failed.is_some() || fw.done() {
            return Ok(());
        }
        let heard = match downlink.as_deref_mut() {
            Some(d) => d.before_plane(&mut fw),
            None => Ok(()),
        };
        if let Err(e) = heard.and_then(|()| fw.push_plane(plane)) {
            failed = Some(e);
        }
        Ok(())
    })?;
    if let Some(e) = failed {
        return Err(e);
    }
    fw.finish()?;
    Ok((fw, sim))
}

/// Runs the firmware on a `.dat` file, plane by plane (hearing the host
/// between planes when given a `downlink`).
#[allow(clippy::too_many_arguments)]
pub fn run_on_dat<L: Link>(
    path: &std::path::Path,
    width: u16,
    height: u16,
    opts: spiv_formats::dat::DatOptions,
    cfg: Config,
    link: L,
    keep: bool,
    mut downlink: Option<&mut ControlStream>,
) -> Result<Firmware<L>, Error> {
    let mut r = spiv_formats::dat::DatReader::open(path, width, height, opts)?;
    let mut fw = Firmware::new(r.width(), r.height(), cfg, link)?;
    if keep {
        fw.keep = Some(Vec::new());
    }
    let mut plane = vec![0u8; r.out_plane_bytes()];
    while !fw.done() && r.read_plane(&mut plane)? {
        if let Some(d) = downlink.as_deref_mut() {
            d.before_plane(&mut fw)?;
        }
        fw.push_plane(&plane)?;
    }
    fw.finish()?;
    Ok(fw)
}

/// Every step the live loop can take now ([`LadderFirmware::step`]),
/// hearing the host (and, pacing, waiting for it) before each pair.
fn drain<L: Link>(
    fw: &mut LadderFirmware<L>,
    mut downlink: Option<&mut ControlStream>,
) -> Result<(), Error> {
    loop {
        if let (Some(i), Some(d)) = (fw.pair_due(), downlink.as_deref_mut()) {
            d.before_pair(fw, i)?;
        }
        if fw.done() || !fw.step()? {
            return Ok(());
        }
    }
}

/// Runs the live loop ([`crate::ladder`]) on a `.dat` file, plane by
/// plane, hearing the host before each pair when given a `downlink`.
pub fn run_ladder_on_dat<L: Link>(
    path: &std::path::Path,
    (width, height): (u16, u16),
    opts: spiv_formats::dat::DatOptions,
    cfg: LadderConfig,
    link: L,
    mut downlink: Option<&mut ControlStream>,
) -> Result<LadderFirmware<L>, Error> {
    let mut r = spiv_formats::dat::DatReader::open(path, width, height, opts)?;
    let mut fw = LadderFirmware::new((r.width(), r.height()), cfg, link)?;
    let mut plane = vec![0u8; r.out_plane_bytes()];
    while !fw.done() && r.read_plane(&mut plane)? {
        fw.take(&plane)?;
        drain(&mut fw, downlink.as_deref_mut())?;
    }
    fw.end()?;
    drain(&mut fw, downlink)?;
    fw.finish()?;
    Ok(fw)
}

/// Runs the live loop on a simulated scene, the planes streamed from the
/// sensor; with `cfg.pairs`, the scene lasts as long as the last pair
/// needs.
pub fn run_ladder_on_scene<L: Link>(
    req: &crate::simulation::Request,
    cfg: LadderConfig,
    link: L,
    mut downlink: Option<&mut ControlStream>,
) -> Result<LadderFirmware<L>, Error> {
    let mut req = req.clone();
    if let Some(mid) = cfg.pairs.and_then(|p| cfg.mid(p.max(1) - 1)) {
        let lead = spiv_core::rungs::lead(cfg.longest, cfg.cold_reach);
        req.ticks = Some(mid.saturating_add(lead).saturating_add(1));
    }
    let mut fw = LadderFirmware::new((req.scene.width, req.scene.height), cfg, link)?;
    let mut failed: Option<Error> = None;
    crate::simulation::simulate(
        &req,
        |_, _| {},
        |plane| {
            if failed.is_some() || fw.done() {
                return Ok(());
            }
            if let Err(e) = fw
                .take(plane)
                .and_then(|()| drain(&mut fw, downlink.as_deref_mut()))
            {
                failed = Some(e);
            }
            Ok(())
        },
    )?;
    if let Some(e) = failed {
        return Err(e);
    }
    fw.end()?;
    drain(&mut fw, downlink)?;
    fw.finish()?;
    Ok(fw)
}

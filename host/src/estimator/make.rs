//! What the host reads of the pairs the sidecar's state makes
//! ([`spiv_core::pairs`]: the core's static-light model and event
//! ring over owned buffers, each pair as the last ask heard says): a
//! [`CorePair`] as the estimator's [`PairInput`], and the one pair of a
//! stretch of planes held in memory ([`input_of`]).

use spiv_core::pairs::{CorePair, PairMaker, LIGHT_TRAIN};
use spiv_core::Error;

use super::control::{Ask, Heard};
use super::events::{upright, Events};
use super::ladder::PairInput;
use crate::reconstruct::Planes;
use spiv_estimator::units::PerTick;

/// What the estimator reads of `pair`: its rung frames upright, cropped
/// to `crop` columns, in spikes; its events ([`Events`]); and `start`, the
/// field its rung frames followed, when it has rung frames (rows stored
/// bottom-up when `flip`).
pub fn pair_input(pair: &CorePair, crop: usize, flip: bool, start: Option<&PerTick>) -> PairInput {
    let (w, h) = (usize::from(pair.size.0), usize::from(pair.size.1));
    let crop = crop.min(w);
    let mut input = PairInput::default();
    if let (Some(field), false) = (start, pair.rungs.is_empty()) {
        input.rungs = pair
            .rungs
            .iter()
            .map(|(s, [a, b])| {
                let f = |x: &Vec<i16>| upright(x, w, h, crop, flip);
                (u32::from(*s), [f(a), f(b)])
            })
            .collect();
        input.start = Some(field.clone());
    }
    if let Some(ev) = &pair.events {
        input.events = Some(Events::from_ticks(
            (w, h),
            crop,
            flip,
            u64::from(ev.first),
            ev.ticks.clone(),
            ev.rates.clone(),
        ));
    }
    input
}

/// The input of the one pair at `mid` of `planes` (a whole stretch held in
/// memory) as the core makes it when asked `ask` (through the wire at
/// once, [`Heard::of`]): the model trained on the stretch's planes played
/// backwards, then every plane taken in order.
pub fn input_of(planes: &Planes, mid: u64, ask: &Ask, reach: u32) -> Result<PairInput, Error> {
    let heard = Heard::of(ask, (planes.width, planes.height), planes.flip)
        .map_err(|_| Error::BadParam(spiv_core::error::ParamError::Motion))?;
    let (w, h) = (planes.width, planes.height);
    let pb = (usize::from(w) * usize::from(h) / 8).max(1);
    let n = planes.data.len() / pb;
    let first = u32::try_from(planes.first).map_err(|_| Error::TickOverflow)?;
    let mut m = PairMaker::new((w, h), first, n + 1)?;
    let all: Vec<&[u8]> = planes.data.chunks_exact(pb).collect();
    m.train(&all[1.min(all.len())..], LIGHT_TRAIN)?;
    for p in &all {
        m.push(p)?;
    }
    let mid = u32::try_from(mid).map_err(|_| Error::TickOverflow)?;
    let reach = u16::try_from(reach).unwrap_or(u16::MAX);
    let pair = m.make(mid, &heard.asked(), reach)?;
    let crop = usize::from(planes.crop_width);
    Ok(pair_input(&pair, crop, planes.flip, heard.start.as_ref()))
}

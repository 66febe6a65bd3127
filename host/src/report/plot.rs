//! Plots of a run, as PNG (plotters, bitmap backend; the font is bundled so
//! a fresh machine needs no system fonts): the u(y) profile against the
//! truth, and the vector field over its frame.

use std::path::Path;
use std::sync::Once;

use plotters::prelude::*;
use plotters::style::{register_font, FontStyle};

use crate::metrics::ProfileRow;
use crate::Error;
use spiv_formats::{State, Vector};

/// A plotting failure writing `path` (plotters' errors are generic over
/// backends, so they arrive as text).
pub fn plot_error(path: &Path, msg: String) -> Error {
    Error::Plot {
        path: format!("plot {}", path.display()),
        msg,
    }
}

fn err(path: &Path) -> impl Fn(String) -> Error + '_ {
    move |msg| plot_error(path, msg)
}

static FONT: Once = Once::new();

/// Registers the bundled font for plotters' "sans-serif" (idempotent).
pub fn ensure_font() {
    font();
}

fn font() {
    FONT.call_once(|| {
        // DejaVu Sans (Bitstream Vera licence, host/assets/).
        let _ = register_font(
            "sans-serif",
            FontStyle::Normal,
            include_bytes!("../../assets/DejaVuSans.ttf"),
        );
    });
}

/// One measured profile: its name, colour and rows.
#[derive(Debug)]
pub struct Series<'a> {
    /// Legend text.
    pub name: &'a str,
    /// Colour.
    pub color: RGBColor,
    /// Rows (height above the wall, measured u).
    pub rows: &'a [ProfileRow],
}

/// The u(y) profile: the truth as a line, each series as points, the glare
/// band shaded below `glare_limit` px above the wall.
pub fn profile(
    path: &Path,
    title: &str,
    truth: &[(f64, f64)],
    series: &[Series<'_>],
    glare_limit: f64,
) -> Result<(), Error> {
    font();
    let e = err(path);
    let root = BitMapBackend::new(path, (720, 560)).into_drawing_area();
    root.fill(&WHITE).map_err(|x| e(x.to_string()))?;
    let ymax = truth.iter().map(|t| t.0).fold(1.0, f64::max);
    let mut umax = truth.iter().map(|t| t.1).fold(1.0, f64::max);
    for s in series {
        for r in s.rows {
            if let Some(m) = r.measured {
                umax = umax.max(m);
            }
        }
    }
    let umin = series
        .iter()
        .flat_map(|s| s.rows.iter().filter_map(|r| r.measured))
        .fold(0.0, f64::min);
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d(umin - 0.5..umax * 1.1 + 0.5, 0.0..ymax)
        .map_err(|x| e(x.to_string()))?;
    chart
        .configure_mesh()
        .x_desc("u, px per pair")
        .y_desc("height above the wall, px")
        .draw()
        .map_err(|x| e(x.to_string()))?;
    chart
        .draw_series(std::iter::once(Rectangle::new(
            [(umin - 0.5, 0.0), (umax * 1.1 + 0.5, glare_limit)],
            RGBColor(255, 236, 179).filled(),
        )))
        .map_err(|x| e(x.to_string()))?
        .label("glare band")
        .legend(|(x, y)| {
            Rectangle::new(
                [(x, y - 5), (x + 14, y + 5)],
                RGBColor(255, 236, 179).filled(),
            )
        });
    chart
        .draw_series(LineSeries::new(
            truth.iter().map(|&(y, u)| (u, y)),
            BLACK.stroke_width(2),
        ))
        .map_err(|x| e(x.to_string()))?
        .label("truth")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 14, y)], BLACK.stroke_width(2)));
    for s in series {
        let c = s.color;
        chart
            .draw_series(s.rows.iter().filter_map(|r| {
                r.measured
                    .map(|m| Circle::new((m, r.y_wall), 4, c.filled()))
            }))
            .map_err(|x| e(x.to_string()))?
            .label(s.name)
            .legend(move |(x, y)| Circle::new((x + 7, y), 4, c.filled()));
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(|x| e(x.to_string()))?;
    root.present().map_err(|x| e(x.to_string()))
}

/// What a [`vectors`] plot says above its frame.
#[derive(Debug, Clone, Copy)]
pub struct VectorCaption<'a> {
    /// The title (short: it must fit over the frame).
    pub title: &'a str,
    /// One px per pair of displacement in the unit shown by the scale
    /// arrow, and that unit (`None`: px per pair).
    pub unit: Option<(f64, &'a str)>,
}

/// The arrow scale that draws the median valid displacement of `field`
/// (px per pair) as 0.6 of the node spacing `step` (px), never below 1.
pub fn arrow_scale(field: &[Vector], step: usize) -> f64 {
    let mut d: Vec<f64> = field
        .iter()
        .filter(|v| v.state == State::Valid)
        .map(|v| v.u.hypot(v.v))
        .filter(|x| x.is_finite() && *x > 0.0)
        .collect();
    d.sort_by(f64::total_cmp);
    d.get(d.len() / 2)
        .map_or(1.0, |&m| (0.6 * step as f64 / m).max(1.0))
}

/// The vectors over their frame (gray levels `0..=full_scale`, upright,
/// scaled 2×), arrows `scale` times their displacement; valid yellow,
/// replaced orange, flag 2 a red dot; above, the title and a scale arrow
/// of a round length near the median valid displacement.
pub fn vectors(
    path: &Path,
    frame: &[u16],
    (width, height): (u32, u32),
    full_scale: u16,
    field: &[Vector],
    scale: f64,
    caption: VectorCaption<'_>,
) -> Result<(), Error> {
    font();
    let e = err(path);
    let k = 2u32;
    let top = CAPTION;
    let root = BitMapBackend::new(path, (width * k, height * k + top as u32)).into_drawing_area();
    root.fill(&WHITE).map_err(|x| e(x.to_string()))?;
    let fs = f64::from(full_scale.max(1));
    for i in 0..height {
        for j in 0..width {
            let g =
                (f64::from(frame[(i * width + j) as usize]) / fs * 255.0).clamp(0.0, 255.0) as u8;
            for (di, dj) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
                root.draw_pixel(
                    ((j * k + dj) as i32, (i * k + di) as i32 + top),
                    &RGBColor(g, g, g),
                )
                .map_err(|x| e(x.to_string()))?;
            }
        }
    }
    let kk = f64::from(k);
    let arrow = |root: &DrawingArea<BitMapBackend, plotters::coord::Shift>, p0, d, color| {
        draw_arrow(root, p0, d, color).map_err(|x| e(x.to_string()))
    };
    for v in field {
        let (x0, y0) = ((v.x + 0.5) * kk, (v.y + 0.5) * kk + f64::from(top));
        if v.state == State::Invalid {
            root.draw(&Circle::new((x0 as i32, y0 as i32), 2, RED.filled()))
                .map_err(|x| e(x.to_string()))?;
            continue;
        }
        let color = if v.state == State::Valid {
            RGBColor(255, 221, 0)
        } else {
            RGBColor(255, 140, 0)
        };
        arrow(&root, (x0, y0), (v.u * scale * kk, v.v * scale * kk), color)?;
    }
    // The scale arrow: a round displacement near the median valid one.
    let mut d: Vec<f64> = field
        .iter()
        .filter(|v| v.state == State::Valid)
        .map(|v| v.u.hypot(v.v))
        .filter(|x| x.is_finite() && *x > 0.0)
        .collect();
    d.sort_by(f64::total_cmp);
    let (per, unit) = caption.unit.unwrap_or((1.0, "px per pair"));
    let text = |t: String, x: i32| {
        root.draw(&Text::new(t, (x, 6), ("sans-serif", 15).into_font()))
            .map_err(|x| e(x.to_string()))
    };
    text(caption.title.to_string(), 6)?;
    if let Some(&median) = d.get(d.len() / 2) {
        let in_unit = ticks(0.0, 2.5 * median * per);
        let reference = in_unit
            .iter()
            .copied()
            .filter(|&t| t > 0.0)
            .min_by(|a, b| {
                (a / per - median)
                    .abs()
                    .total_cmp(&(b / per - median).abs())
            })
            .unwrap_or(median * per);
        let len = reference / per * scale * kk;
        let x = f64::from(width * k) - len - 150.0;
        arrow(&root, (x.max(0.0), 14.0), (len, 0.0), RGBColor(0, 0, 0))?;
        let step = if in_unit.len() > 1 {
            in_unit[1] - in_unit[0]
        } else {
            reference
        };
        text(
            format!("{} {unit}", tick_label(reference, step)),
            (x.max(0.0) + len) as i32 + 8,
        )?;
    }
    root.present().map_err(|x| e(x.to_string()))
}

plotters::style::colors::colormaps::def_linear_colormap! {
    BlueWhiteRed,
    RGBColor,
    "A diverging map for signed values: blue below zero, white at zero, red above.",
    ( 59,  76, 192),
    (221, 221, 221),
    (180,   4,  38)
}

/// A scalar on the PIV nodes, for [`node_map`].
#[derive(Debug, Clone, Copy)]
pub struct NodeScalar<'a> {
    /// One value per node, row-major (NaN: none).
    pub values: &'a [f64],
    /// What it is, for the title (short: it must fit over the map).
    pub name: &'a str,
    /// Its unit, for the colour bar.
    pub unit: &'a str,
    /// Signed (a diverging map centred on 0) or not (viridis from 0).
    pub signed: bool,
    /// The end of the colour scale (`None`: the largest magnitude of
    /// `values`); frames of one movie share one.
    pub top: Option<f64>,
    /// The pixel size, mm: the axes in mm (`None`: in px).
    pub mm_per_px: Option<f64>,
    /// Label the y axis up from the bottom row (the image is drawn as the
    /// camera saw it either way).
    pub y_up: bool,
}

/// Pixels of the title above a [`node_map`].
const CAPTION: i32 = 28;
/// Pixels left of the map (the y axis and its labels).
const LEFT: i32 = 58;
/// Pixels below the map (the x axis, its labels and its name).
const BOTTOM: i32 = 44;
/// Pixels right of the map (the colour bar and its labels).
const RIGHT: i32 = 96;
/// Scale of a [`node_map`] over its frame.
const SCALE: i32 = 2;

/// A scalar field of the nodes of `grid` as cells of its colour over a
/// `width × height` frame (scaled 2×), with axes (px, or mm when
/// calibrated; y down, as the image), a colour bar in the scalar's unit
/// and a short title; nodes without a value dark gray, `glare` pixels
/// (upright, `width × height`) hatched in black, which no colour of the
/// maps is.
pub fn node_map(
    path: &Path,
    (width, height): (u32, u32),
    grid: &spiv_formats::grid::Grid,
    s: NodeScalar<'_>,
    glare: &[bool],
) -> Result<(), Error> {
    let e = err(path);
    let size = node_map_size((width, height));
    let root = BitMapBackend::new(path, size).into_drawing_area();
    draw_node_map(&root, (width, height), grid, s, glare).map_err(&e)?;
    root.present().map_err(|x| e(x.to_string()))
}

/// [`node_map`] into memory: its RGB pixels (8 bits each, row-major) and
/// its size.
pub fn node_map_rgb(
    (width, height): (u32, u32),
    grid: &spiv_formats::grid::Grid,
    s: NodeScalar<'_>,
    glare: &[bool],
) -> Result<(Vec<u8>, (u32, u32)), Error> {
    let e = err(Path::new("(memory)"));
    let size = node_map_size((width, height));
    let mut rgb = vec![0u8; size.0 as usize * size.1 as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, size).into_drawing_area();
        draw_node_map(&root, (width, height), grid, s, glare).map_err(&e)?;
        root.present().map_err(|x| e(x.to_string()))?;
    }
    Ok((rgb, size))
}

/// The size of a [`node_map`] of a `width × height` frame, px.
pub fn node_map_size((width, height): (u32, u32)) -> (u32, u32) {
    let k = SCALE as u32;
    (
        width * k + (LEFT + RIGHT) as u32,
        height * k + (CAPTION + BOTTOM) as u32,
    )
}

/// Round tick values over `0..=span`: steps of 1, 2 or 5 × 10ⁿ, about
/// five of them.
fn ticks(lo: f64, hi: f64) -> Vec<f64> {
    let span = hi - lo;
    if !(span.is_finite() && span > 0.0) {
        return vec![lo];
    }
    let raw = span / 5.0;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * mag)
        .find(|&st| st >= raw)
        .unwrap_or(10.0 * mag);
    let first = (lo / step).ceil() as i64;
    let last = (hi / step + 1e-9).floor() as i64;
    (first..=last).map(|i| i as f64 * step).collect()
}

/// A tick label: as few decimals as the step needs.
fn tick_label(v: f64, step: f64) -> String {
    let d = if step >= 1.0 {
        0
    } else {
        (-step.log10().floor()) as usize
    };
    format!("{v:.d$}")
}

fn draw_node_map<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    (width, height): (u32, u32),
    grid: &spiv_formats::grid::Grid,
    s: NodeScalar<'_>,
    glare: &[bool],
) -> Result<(), String> {
    use plotters::style::colors::colormaps::ViridisRGB;
    font();
    let e = |x: DrawingAreaErrorKind<DB::ErrorType>| x.to_string();
    let (k, top_px, left) = (SCALE, CAPTION, LEFT);
    let (mw, mh) = (width as i32 * k, height as i32 * k);
    root.fill(&WHITE).map_err(e)?;
    let finite = s.values.iter().copied().filter(|v| v.is_finite());
    let (lo, hi) = finite.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
        (a.min(v), b.max(v))
    });
    let top = s
        .top
        .unwrap_or(if s.signed { lo.abs().max(hi.abs()) } else { hi });
    let colour = |v: f64| match (v.is_finite() && top > 0.0, s.signed) {
        (false, _) => RGBColor(60, 60, 60),
        (true, true) => BlueWhiteRed::get_color_normalized(v.clamp(-top, top), -top, top),
        (true, false) => ViridisRGB::get_color_normalized(v.clamp(0.0, top), 0.0, top),
    };
    let half = grid.step as f64 / 2.0;
    for r in 0..grid.ny {
        for c in 0..grid.nx {
            let v = s.values.get(r * grid.nx + c).copied().unwrap_or(f64::NAN);
            let (x, y) = grid.centre(r, c);
            let corner = |dx: f64, dy: f64| {
                (
                    ((x + dx) * f64::from(k)) as i32 + left,
                    ((y + dy) * f64::from(k)) as i32 + top_px,
                )
            };
            root.draw(&Rectangle::new(
                [corner(-half, -half), corner(half, half)],
                colour(v).filled(),
            ))
            .map_err(e)?;
        }
    }
    // Glare: black diagonal hatching (no colour of either map is black),
    // so the field shows between the lines.
    let (wu, hu) = (width as usize, height as usize);
    for (i, _) in glare.iter().enumerate().filter(|(_, &g)| g) {
        let (r, c) = (i / wu, i % wu);
        if r < hu && (r + c) % 4 == 0 {
            let (px, py) = (c as i32 * k + left, r as i32 * k + top_px);
            for (dx, dy) in [(0, 0), (1, 1)] {
                root.draw_pixel((px + dx, py + dy), &BLACK).map_err(e)?;
            }
        }
    }
    draw_axes(root, (width, height), &s).map_err(e)?;
    let (b_lo, b_hi) = if s.signed { (-top, top) } else { (0.0, top) };
    draw_colour_bar(root, (mw, mh), (b_lo, b_hi), s.unit, &colour).map_err(e)?;
    let marked = if glare.contains(&true) {
        "; hatched: glare"
    } else {
        ""
    };
    let empty = if lo.is_finite() { "" } else { " (no value)" };
    root.draw(&Text::new(
        format!("{}{empty}{marked}", s.name),
        (6, 6),
        ("sans-serif", 15).into_font(),
    ))
    .map_err(e)
}

/// A pixel of a [`node_map`]'s frame area: left of it, above it.
fn map_origin() -> (i32, i32) {
    (LEFT, CAPTION)
}

/// The frame around a [`node_map`], its ticks and labels in mm
/// (calibrated) or px, y down or up as `s` says.
fn draw_axes<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    (width, height): (u32, u32),
    s: &NodeScalar<'_>,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let k = SCALE;
    let (left, top_px) = map_origin();
    let (mw, mh) = (width as i32 * k, height as i32 * k);
    root.draw(&Rectangle::new(
        [(left - 1, top_px - 1), (left + mw, top_px + mh)],
        BLACK.stroke_width(1),
    ))?;
    let (per, unit) = match s.mm_per_px {
        Some(mm) => (mm, "mm"),
        None => (1.0, "px"),
    };
    let small = ("sans-serif", 12).into_font();
    let step_of = |t: &[f64]| if t.len() > 1 { t[1] - t[0] } else { 1.0 };
    let xt = ticks(0.0, f64::from(width) * per);
    for &v in &xt {
        let px = left + (v / per * f64::from(k)) as i32;
        root.draw(&PathElement::new(
            vec![(px, top_px + mh), (px, top_px + mh + 4)],
            BLACK,
        ))?;
        root.draw(&Text::new(
            tick_label(v, step_of(&xt)),
            (px - 8, top_px + mh + 6),
            small.clone(),
        ))?;
    }
    root.draw(&Text::new(
        format!("x, {unit}"),
        (left + mw / 2 - 14, top_px + mh + 24),
        small.clone(),
    ))?;
    let yt = ticks(0.0, f64::from(height) * per);
    for &v in &yt {
        let from_top = if s.y_up {
            f64::from(height) - v / per
        } else {
            v / per
        };
        let py = top_px + (from_top * f64::from(k)) as i32;
        root.draw(&PathElement::new(
            vec![(left - 5, py), (left - 1, py)],
            BLACK,
        ))?;
        root.draw(&Text::new(
            tick_label(v, step_of(&yt)),
            (left - 40, py - 6),
            small.clone(),
        ))?;
    }
    root.draw(&Text::new(
        format!("y, {unit} ({})", if s.y_up { "up" } else { "down" }),
        (2, top_px + mh + 24),
        small,
    ))?;
    Ok(())
}

/// The colour bar right of a `mw × mh` map: `colour` from `lo` (bottom)
/// to `hi` (top), ticks and `unit` below it.
fn draw_colour_bar<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    (mw, mh): (i32, i32),
    (lo, hi): (f64, f64),
    unit: &str,
    colour: &dyn Fn(f64) -> RGBColor,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let (left, top_px) = map_origin();
    let (bx, bw) = (left + mw + 14, 14);
    let small = ("sans-serif", 12).into_font();
    if hi > lo && hi.is_finite() && lo.is_finite() {
        for i in 0..mh {
            let v = hi - (hi - lo) * (f64::from(i) + 0.5) / f64::from(mh);
            root.draw(&Rectangle::new(
                [(bx, top_px + i), (bx + bw, top_px + i + 1)],
                colour(v).filled(),
            ))?;
        }
        let bt = ticks(lo, hi);
        let step = if bt.len() > 1 { bt[1] - bt[0] } else { 1.0 };
        for &v in &bt {
            let py = top_px + ((hi - v) / (hi - lo) * f64::from(mh)) as i32;
            root.draw(&PathElement::new(
                vec![(bx + bw, py), (bx + bw + 3, py)],
                BLACK,
            ))?;
            root.draw(&Text::new(
                tick_label(v, step),
                (bx + bw + 5, py - 6),
                small.clone(),
            ))?;
        }
    }
    root.draw(&Rectangle::new(
        [(bx, top_px), (bx + bw, top_px + mh)],
        BLACK.stroke_width(1),
    ))?;
    root.draw(&Text::new(unit.to_string(), (bx, top_px + mh + 6), small))?;
    Ok(())
}

/// An arrow from `(x0, y0)` by `(dx, dy)` px, 2 px wide, its head 0.3 of
/// its length (at most 8 px).
fn draw_arrow<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    (x0, y0): (f64, f64),
    (dx, dy): (f64, f64),
    color: RGBColor,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let p0 = (x0 as i32, y0 as i32);
    let p1 = ((x0 + dx) as i32, (y0 + dy) as i32);
    root.draw(&PathElement::new(vec![p0, p1], color.stroke_width(2)))?;
    let len = (dx * dx + dy * dy).sqrt().max(1e-9);
    let (ux, uy) = (dx / len, dy / len);
    let hl = (len * 0.3).min(8.0);
    for s in [-1.0, 1.0] {
        let hx = x0 + dx - hl * (ux - s * 0.5 * uy);
        let hy = y0 + dy - hl * (uy + s * 0.5 * ux);
        root.draw(&PathElement::new(
            vec![p1, (hx as i32, hy as i32)],
            color.stroke_width(2),
        ))?;
    }
    Ok(())
}

//! The plotters boilerplate shared by the commands' PNG plots: a labelled mesh, a framed legend,
//! legend markers, and a check that a written PNG holds a real picture.

use anyhow::{Context, Result};
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use std::path::Path;

/// A chart over f64 x f64 on a PNG bitmap (every chart of the simulator's plots).
pub type Chart<'a, 'b> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// Draws the grid with axis descriptions (`y_desc` may be empty).
pub fn mesh(chart: &mut Chart<'_, '_>, x_desc: &str, y_desc: &str) -> Result<()> {
    let mut m = chart.configure_mesh();
    m.x_desc(x_desc);
    if !y_desc.is_empty() {
        m.y_desc(y_desc);
    }
    m.draw()?;
    Ok(())
}

/// Draws the legend of the labelled series: half-transparent white box with a black frame at
/// `pos`.
pub fn legend<'a, 'b: 'a>(chart: &mut Chart<'a, 'b>, pos: SeriesLabelPosition) -> Result<()> {
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .position(pos)
        .draw()?;
    Ok(())
}

/// Legend marker of a line series: a short stroke in `color`.
pub fn line_marker(color: RGBColor, width: u32) -> impl Fn((i32, i32)) -> PathElement<(i32, i32)> {
    move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(width))
}

/// Legend marker of a point series: a filled dot in `color`.
pub fn dot_marker(color: RGBColor) -> impl Fn((i32, i32)) -> Circle<(i32, i32), i32> {
    move |(x, y)| Circle::new((x + 10, y), 3, color.filled())
}

/// Cells of a heat map on a regular grid: each sample is the centre of a dx x dy cell, and the
/// axes reach half a cell beyond the first and last samples.
pub struct Cells {
    /// Cell width (x step).
    pub dx: f64,
    /// Cell height (y step; 10 % of |y| or 0.1 for a single row).
    pub dy: f64,
    /// x axis range.
    pub x: std::ops::Range<f64>,
    /// y axis range.
    pub y: std::ops::Range<f64>,
}

/// The cells of samples at `xs` (at least two, increasing) by `ny` rows from `y_first` to
/// `y_last`.
pub fn cells(xs: &[f64], y_first: f64, y_last: f64, ny: usize) -> Cells {
    let (x0, x1) = (xs[0], xs[xs.len() - 1]);
    let dx = xs[1] - xs[0];
    let dy = if ny > 1 {
        (y_last - y_first) / (ny - 1) as f64
    } else {
        y_first.abs().max(1.0) * 0.1
    };
    Cells {
        dx,
        dy,
        x: x0 - dx / 2.0..x1 + dx / 2.0,
        y: y_first - dy / 2.0..y_last + dy / 2.0,
    }
}

/// Diverging colour of `t` in [-1, 1]: blue (-1) through white (0) to red (1); clipped.
pub fn diverging(t: f64) -> RGBColor {
    let t = t.clamp(-1.0, 1.0);
    if t >= 0.0 {
        let gb = (255.0 * (1.0 - t)) as u8;
        RGBColor(255, gb, gb)
    } else {
        let rg = (255.0 * (1.0 + t)) as u8;
        RGBColor(rg, rg, 255)
    }
}

/// Sequential colour of `t` in [0, 1]: white (0) to red (1); clipped.
pub fn white_to_red(t: f64) -> RGBColor {
    diverging(t.clamp(0.0, 1.0))
}

/// Width of a heat map's colour bar, px (split off the right of the picture).
pub const COLOUR_BAR_PX: u32 = 130;

/// Draws a vertical colour bar into `area`: the values `lo..hi` (axis with ticks, described by
/// `label`) in the colours `colour(value)` the heat map uses. `top_px` aligns it below the
/// heat map's caption.
pub fn colour_bar(
    area: &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>,
    lo: f64,
    hi: f64,
    label: &str,
    top_px: u32,
    colour: impl Fn(f64) -> RGBColor,
) -> Result<()> {
    let (lo, hi) = if hi > lo { (lo, hi) } else { (lo, lo + 1.0) };
    let mut chart = ChartBuilder::on(area)
        .margin_top(top_px)
        .margin_bottom(40)
        .margin_right(10)
        .y_label_area_size(80)
        .build_cartesian_2d(0.0..1.0, lo..hi)?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .disable_y_mesh()
        .x_labels(0)
        .y_labels(9)
        .y_label_style(("sans-serif", 12).into_font())
        .axis_desc_style(("sans-serif", 13).into_font())
        .y_desc(label)
        .draw()?;
    const STEPS: usize = 200;
    let dy = (hi - lo) / STEPS as f64;
    chart.draw_series((0..STEPS).map(|i| {
        let y = lo + i as f64 * dy;
        Rectangle::new([(0.0, y), (1.0, y + dy)], colour(y + dy / 2.0).filled())
    }))?;
    Ok(())
}

/// Colour-blind-safe palette (Okabe-Ito based) used for runs in every plot.
pub const COLORS: [RGBColor; 6] = [
    RGBColor(120, 120, 120),
    RGBColor(220, 50, 32),
    RGBColor(0, 114, 178),
    RGBColor(230, 159, 0),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
];

/// Facts about a written PNG, to check that a plot holds a picture.
#[derive(Clone, Copy, Debug)]
pub struct PngCheck {
    /// File size, bytes.
    pub bytes: u64,
    /// Width x height, px.
    pub size_px: (u32, u32),
    /// Number of distinct colours (counted up to 4096).
    pub colors: usize,
    /// Fraction of pixels that are not the most common colour (the background).
    pub ink: f64,
}

/// Decodes a PNG and measures it (fails if it is not a valid PNG).
pub fn check_png(path: &Path) -> Result<PngCheck> {
    let bytes = std::fs::metadata(path)
        .with_context(|| format!("{}", path.display()))?
        .len();
    let img = image::open(path)
        .with_context(|| format!("decoding {}", path.display()))?
        .to_rgb8();
    let mut counts: std::collections::HashMap<[u8; 3], usize> = std::collections::HashMap::new();
    for p in img.pixels() {
        if counts.len() < 4096 || counts.contains_key(&p.0) {
            *counts.entry(p.0).or_default() += 1;
        }
    }
    let total = (img.width() as usize * img.height() as usize).max(1);
    let background = counts.values().copied().max().unwrap_or(0);
    Ok(PngCheck {
        bytes,
        size_px: (img.width(), img.height()),
        colors: counts.len(),
        ink: 1.0 - background as f64 / total as f64,
    })
}

/// Fails unless `path` is a valid PNG of a real plot: more than 5 kB, at least `min_colors`
/// distinct colours and at least 1 % of the pixels off the background colour (a blank or
/// single-colour image fails all three).
pub fn assert_real_plot(path: &Path, min_colors: usize) -> Result<PngCheck> {
    let c = check_png(path)?;
    anyhow::ensure!(
        c.bytes > 5_000 && c.colors >= min_colors && c.ink > 0.01,
        "{} does not look like a plot: {c:?}",
        path.display()
    );
    Ok(c)
}

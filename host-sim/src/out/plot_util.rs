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

//! What every figure shares: fonts, rendering to PNG and SVG, colours, tick labels, the legend.

use image::ImageEncoder;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

pub(super) const FONT: &str = "sans-serif";
/// Errors below this are drawn as this (log10 of an exact zero).
pub(super) const ERROR_FLOOR: f64 = 1e-16;

/// Registers DejaVu Sans for the bitmap backend (idempotent).
pub(super) fn ensure_font() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        // Both are valid TrueType files shipped inside the crate; a failure leaves text undrawn
        // in PNGs but never fails a plot.
        let _ = plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular());
        let _ = plotters::style::register_font(FONT, FontStyle::Bold, dejavu::sans::bold());
    });
}

/// A plotting backend's error as the trainer's.
pub(super) fn pe<E: std::fmt::Display>(e: E) -> crate::Error {
    crate::Error::Plot(format!("plot: {e}"))
}

/// One figure, drawable on any backend.
pub(super) trait Figure {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> crate::Result<()>;
}

/// Draws `fig` to `dir/stem.png` and `dir/stem.svg`. Both are drawn in memory and written as
/// every output is (`crate::io::write_atomically`): never through a symbolic link or into a FIFO
/// that holds a figure's name, never over a file the run reads, never half-written.
pub(super) fn render<F: Figure>(dir: &Path, stem: &str, size: (u32, u32), fig: &F) -> crate::Result<Vec<PathBuf>> {
    ensure_font();
    crate::io::create_output_dir(dir)?;
    let png = dir.join(format!("{stem}.png"));
    let svg = dir.join(format!("{stem}.svg"));
    let png_bytes = render_png(size, fig).map_err(|e| e.context(png.display().to_string()))?;
    crate::io::write_atomically(&png, &png_bytes)?;
    let svg_text = render_svg_string(size, fig).map_err(|e| e.context(svg.display().to_string()))?;
    crate::io::write_atomically(&svg, svg_text.as_bytes())?;
    Ok(vec![png, svg])
}

/// Draws `fig` as a PNG file's bytes (RGB, as the bitmap backend saves it).
fn render_png<F: Figure>(size: (u32, u32), fig: &F) -> crate::Result<Vec<u8>> {
    let mut rgb = vec![0u8; size.0 as usize * size.1 as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, size).into_drawing_area();
        root.fill(&WHITE).map_err(pe)?;
        fig.draw(&root)?;
        root.present().map_err(pe)?;
    }
    let mut png = Vec::new();
    image::codecs::png::PngEncoder::new(&mut png).write_image(&rgb, size.0, size.1, image::ColorType::Rgb8).map_err(pe)?;
    Ok(png)
}

/// Draws `fig` as an SVG document in memory (for inline use in HTML).
pub(super) fn render_svg_string<F: Figure>(size: (u32, u32), fig: &F) -> crate::Result<String> {
    ensure_font();
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, size).into_drawing_area();
        root.fill(&WHITE).map_err(pe)?;
        fig.draw(&root)?;
        root.present().map_err(pe)?;
    }
    Ok(buf)
}

pub(super) fn log_err(e: f64) -> f64 {
    if e.is_nan() {
        f64::NAN
    } else {
        e.max(ERROR_FLOOR).log10()
    }
}

/// Range of finite values, widened when degenerate; `None` when there are none.
pub(super) fn finite_range<'a>(values: impl IntoIterator<Item = &'a f64>) -> Option<(f64, f64)> {
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for &v in values {
        if v.is_finite() {
            lo = lo.min(v);
            hi = hi.max(v);
        }
    }
    if !lo.is_finite() {
        return None;
    }
    if hi - lo < 1e-12 {
        let pad = if lo.abs() > 1e-12 { lo.abs() * 0.05 } else { 0.5 };
        return Some((lo - pad, hi + pad));
    }
    Some((lo, hi))
}

/// The viridis colour map at t ∈ [0, 1] (piecewise linear through 9 anchors).
pub fn viridis(t: f64) -> RGBColor {
    const ANCHORS: [(u8, u8, u8); 9] = [
        (68, 1, 84),
        (71, 44, 122),
        (59, 81, 139),
        (44, 113, 142),
        (33, 144, 141),
        (39, 173, 129),
        (92, 200, 99),
        (170, 220, 50),
        (253, 231, 37),
    ];
    let t = if t.is_finite() { t.clamp(0.0, 1.0) } else { 0.0 };
    let x = t * (ANCHORS.len() - 1) as f64;
    let i = (x.floor() as usize).min(ANCHORS.len() - 2);
    let f = x - i as f64;
    let lerp = |a: u8, b: u8| (a as f64 + (b as f64 - a as f64) * f).round() as u8;
    let (a, b) = (ANCHORS[i], ANCHORS[i + 1]);
    RGBColor(lerp(a.0, b.0), lerp(a.1, b.1), lerp(a.2, b.2))
}

/// "q1 (rad)" → "q1".
pub(super) fn bare_name(label: &str) -> &str {
    label.split(" (").next().unwrap_or(label).trim()
}

/// A tick label for a linear axis whose values span about `scale`.
pub(super) fn linear_label(v: f64, scale: f64) -> String {
    if v.abs() < 1e-9 * scale.abs().max(f64::MIN_POSITIVE) {
        return "0".into();
    }
    if (1e-3..1e4).contains(&scale.abs()) {
        let digits = (2.0 - scale.abs().log10().floor()).clamp(0.0, 6.0) as usize;
        format!("{v:.digits$}")
    } else {
        format!("{v:.1e}")
    }
}

pub(super) fn fmt_sci(v: f64) -> String {
    if !v.is_finite() {
        return "n/a".into();
    }
    format!("{v:.2e}")
}

/// The tick label of a log10 axis value: 1e-2 at whole exponents, 3e-3 between them.
pub(super) fn pow10_label(v: &f64) -> String {
    if (v - v.round()).abs() < 1e-9 {
        format!("1e{}", v.round() as i64)
    } else {
        format!("{:.0e}", 10f64.powf(*v))
    }
}

/// Before (nominal) and after (calibrated) in every figure that compares them.
pub(super) const BEFORE_COLOR: RGBColor = RGBColor(220, 60, 40);
pub(super) const AFTER_COLOR: RGBColor = RGBColor(30, 100, 220);

pub(super) const METHOD_COLORS: [RGBColor; 8] = [
    RGBColor(120, 120, 120),
    RGBColor(230, 120, 20),
    RGBColor(30, 100, 220),
    RGBColor(130, 60, 180),
    RGBColor(20, 150, 80),
    RGBColor(200, 40, 90),
    RGBColor(0, 150, 170),
    RGBColor(150, 110, 40),
];

/// The legend box every figure draws: upper right, white, framed, labels at `font_size`.
pub(super) fn draw_legend<'a, DB: DrawingBackend + 'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
    font_size: u32,
) -> crate::Result<()> {
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .label_font((FONT, font_size))
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK)
        .draw()
        .map_err(pe)
}

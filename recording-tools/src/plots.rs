//! Line plots and histograms written as both PNG and SVG (plotters), for `rig report`.

use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

/// One line of a plot.
#[derive(Debug, Clone)]
pub struct Series {
    pub label: String,
    pub points: Vec<(f64, f64)>,
}

/// A plot of lines, optionally with labelled horizontal reference lines.
#[derive(Debug, Clone, Default)]
pub struct LinePlot {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub series: Vec<Series>,
    /// (y, label) of dashed horizontal reference lines.
    pub hlines: Vec<(f64, String)>,
    /// x of thin grey vertical markers (a contour's segment ends), the label written at the top.
    pub vlines: Vec<(f64, String)>,
}

/// A histogram: bins as (left edge, right edge, count).
#[derive(Debug, Clone, Default)]
pub struct Histogram {
    pub title: String,
    pub x_label: String,
    pub bins: Vec<(f64, f64, u64)>,
}

const SIZE: (u32, u32) = (1200, 700);
/// Points per series kept in a figure (min/max per bucket keeps the envelope).
const MAX_POINTS: usize = 4000;

fn colour(i: usize) -> RGBColor {
    const C: [RGBColor; 8] = [
        RGBColor(31, 119, 180),
        RGBColor(214, 39, 40),
        RGBColor(44, 160, 44),
        RGBColor(255, 127, 14),
        RGBColor(148, 103, 189),
        RGBColor(23, 190, 207),
        RGBColor(140, 86, 75),
        RGBColor(0, 0, 0),
    ];
    C[i % C.len()]
}

/// Keeps at most about `max` points: the lowest and highest of each bucket, in x order.
pub fn decimate(points: &[(f64, f64)], max: usize) -> Vec<(f64, f64)> {
    if points.len() <= max || max < 4 {
        return points.to_vec();
    }
    let bucket = points.len().div_ceil(max / 2);
    let mut out = Vec::with_capacity(max + 2);
    for b in points.chunks(bucket) {
        let lo = b.iter().enumerate().min_by(|x, y| x.1 .1.total_cmp(&y.1 .1)).unwrap();
        let hi = b.iter().enumerate().max_by(|x, y| x.1 .1.total_cmp(&y.1 .1)).unwrap();
        let (first, second) = if lo.0 <= hi.0 { (lo, hi) } else { (hi, lo) };
        out.push(*first.1);
        if first.0 != second.0 {
            out.push(*second.1);
        }
    }
    out
}

fn range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let pad = if hi > lo { 0.05 * (hi - lo) } else { lo.abs().max(1.0) * 0.05 };
    (lo - pad, hi + pad)
}

fn err<E: std::fmt::Debug>(e: E) -> String {
    format!("{e:?}")
}

fn draw_lines<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, p: &LinePlot) -> Result<(), String> {
    root.fill(&WHITE).map_err(err)?;
    let series: Vec<Series> = p.series.iter().map(|s| Series { label: s.label.clone(), points: decimate(&s.points, MAX_POINTS) }).collect();
    let (x0, x1) = range(series.iter().flat_map(|s| s.points.iter().map(|q| q.0)));
    let (y0, y1) = range(series.iter().flat_map(|s| s.points.iter().map(|q| q.1)).chain(p.hlines.iter().map(|h| h.0)));
    let mut chart = ChartBuilder::on(&root)
        .caption(&p.title, ("sans-serif", 24))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(80)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(err)?;
    chart.configure_mesh().x_desc(p.x_label.as_str()).y_desc(p.y_label.as_str()).draw().map_err(err)?;
    for (i, s) in series.iter().enumerate() {
        let c = colour(i);
        chart
            .draw_series(LineSeries::new(s.points.iter().copied(), c.stroke_width(2)))
            .map_err(err)?
            .label(s.label.as_str())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
    }
    for (j, (y, label)) in p.hlines.iter().enumerate() {
        let c = colour(series.len() + j);
        let n = 60;
        let dashes = (0..n).step_by(2).map(move |k| {
            let a = x0 + (x1 - x0) * k as f64 / n as f64;
            let b = x0 + (x1 - x0) * (k + 1) as f64 / n as f64;
            PathElement::new(vec![(a, *y), (b, *y)], c.stroke_width(1))
        });
        chart
            .draw_series(dashes)
            .map_err(err)?
            .label(label.as_str())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(1)));
    }
    for (x, label) in p.vlines.iter().filter(|v| v.0 >= x0 && v.0 <= x1) {
        let grey = RGBColor(150, 150, 150);
        chart.draw_series(std::iter::once(PathElement::new(vec![(*x, y0), (*x, y1)], grey.stroke_width(1)))).map_err(err)?;
        chart.draw_series(std::iter::once(Text::new(label.clone(), (*x, y1), ("sans-serif", 12).into_font().color(&grey)))).map_err(err)?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(err)?;
    root.present().map_err(err)
}

fn draw_histogram<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, h: &Histogram) -> Result<(), String> {
    root.fill(&WHITE).map_err(err)?;
    let (x0, x1) = range(h.bins.iter().flat_map(|b| [b.0, b.1]));
    let ymax = h.bins.iter().map(|b| b.2).max().unwrap_or(1).max(1) as f64 * 1.05;
    let mut chart = ChartBuilder::on(&root)
        .caption(&h.title, ("sans-serif", 24))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(80)
        .build_cartesian_2d(x0..x1, 0.0..ymax)
        .map_err(err)?;
    chart.configure_mesh().x_desc(h.x_label.as_str()).y_desc("ticks").draw().map_err(err)?;
    let c = colour(0);
    chart
        .draw_series(h.bins.iter().filter(|b| b.2 > 0).map(|b| Rectangle::new([(b.0, 0.0), (b.1, b.2 as f64)], c.filled())))
        .map_err(err)?;
    root.present().map_err(err)
}

fn both(stem: &Path, draw: impl Fn(&Path, bool) -> Result<(), String>) -> anyhow::Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for (ext, png) in [("png", true), ("svg", false)] {
        let path = stem.with_extension(ext);
        draw(&path, png).map_err(|e| anyhow::anyhow!("drawing {}: {e}", path.display()))?;
        out.push(path);
    }
    Ok(out)
}

/// Writes `stem.png` and `stem.svg`.
pub fn save_lines(p: &LinePlot, stem: &Path) -> anyhow::Result<Vec<PathBuf>> {
    both(stem, |path, png| {
        if png {
            draw_lines(BitMapBackend::new(path, SIZE).into_drawing_area(), p)
        } else {
            draw_lines(SVGBackend::new(path, SIZE).into_drawing_area(), p)
        }
    })
}

/// Writes `stem.png` and `stem.svg`.
pub fn save_histogram(h: &Histogram, stem: &Path) -> anyhow::Result<Vec<PathBuf>> {
    both(stem, |path, png| {
        if png {
            draw_histogram(BitMapBackend::new(path, SIZE).into_drawing_area(), h)
        } else {
            draw_histogram(SVGBackend::new(path, SIZE).into_drawing_area(), h)
        }
    })
}

/// `n` equal bins over [lo, hi] (values outside go to the end bins).
pub fn bin(values: &[f64], lo: f64, hi: f64, n: usize) -> Vec<(f64, f64, u64)> {
    let n = n.max(1);
    let w = if hi > lo { (hi - lo) / n as f64 } else { 1.0 };
    let mut counts = vec![0u64; n];
    for &v in values.iter().filter(|v| v.is_finite()) {
        let k = (((v - lo) / w).floor().max(0.0) as usize).min(n - 1);
        counts[k] += 1;
    }
    counts.into_iter().enumerate().map(|(k, c)| (lo + k as f64 * w, lo + (k + 1) as f64 * w, c)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decimation_keeps_the_envelope() {
        let pts: Vec<(f64, f64)> = (0..100_000).map(|i| (i as f64, ((i * 7919) % 1000) as f64)).collect();
        let d = decimate(&pts, 1000);
        assert!(d.len() <= 1002 && d.len() > 500);
        let max = d.iter().map(|p| p.1).fold(f64::MIN, f64::max);
        let min = d.iter().map(|p| p.1).fold(f64::MAX, f64::min);
        assert_eq!((min, max), (0.0, 999.0));
        assert!(d.windows(2).all(|w| w[0].0 < w[1].0));
    }

    #[test]
    fn binning_counts_every_value_once() {
        let v: Vec<f64> = (0..1000).map(|i| i as f64 * 0.01).collect(); // 0 .. 9.99
        let b = bin(&v, 0.0, 10.0, 10);
        assert!(b.iter().all(|x| x.2 == 100), "{b:?}");
        assert_eq!(bin(&[-5.0, 50.0], 0.0, 10.0, 10).iter().map(|x| x.2).sum::<u64>(), 2);
    }
}

//! The charts of the `accuracy` and `volumetric_bench` examples: plotters drawing into a
//! buffer, labels in a font egui already ships, saved as PNG.

use std::path::Path;

use plotters::{
    coord::{Shift, ranged1d::Ranged, types::RangedCoordf64},
    prelude::*,
};

/// Registers the charts' font ("sans-serif": egui's Ubuntu Light; no system fonts needed).
pub fn register_font() {
    plotters::style::register_font(
        "sans-serif",
        FontStyle::Normal,
        epaint_default_fonts::UBUNTU_LIGHT,
    )
    .map_err(|_| ())
    .expect("the font registers");
}

/// Draws a `w × h` white chart with `draw` and saves it as a PNG at `path`.
pub fn save(w: u32, h: u32, path: &Path, draw: impl FnOnce(&DrawingArea<BitMapBackend<'_>, Shift>)) {
    register_font();
    let mut buffer = vec![0u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, (w, h)).into_drawing_area();
        root.fill(&WHITE).expect("draw");
        draw(&root);
        root.present().expect("draw");
    }
    image::RgbImage::from_raw(w, h, buffer)
        .expect("w × h pixels")
        .save(path)
        .expect("cannot write the chart");
}

/// One series: a line through `points` with a dot on each, in the legend as `label`.
pub fn line_with_points<'a, DB: DrawingBackend + 'a, Y: Ranged<ValueType = f64>>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<RangedCoordf64, Y>>,
    label: &str,
    points: &[(f64, f64)],
    color: RGBAColor,
) {
    chart
        .draw_series(LineSeries::new(points.iter().copied(), color.stroke_width(2)))
        .expect("draw")
        .label(label)
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color));
    chart
        .draw_series(points.iter().map(|&p| Circle::new(p, 4, color.filled())))
        .expect("draw");
}

/// The legend, boxed, at the top right.
pub fn legend<'a, DB: DrawingBackend + 'a, Y: Ranged<ValueType = f64>>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<RangedCoordf64, Y>>,
) {
    legend_at(chart, SeriesLabelPosition::UpperRight);
}

/// The legend, boxed, at `position`.
pub fn legend_at<'a, DB: DrawingBackend + 'a, Y: Ranged<ValueType = f64>>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<RangedCoordf64, Y>>,
    position: SeriesLabelPosition,
) {
    chart
        .configure_series_labels()
        .position(position)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .label_font(("sans-serif", 14))
        .draw()
        .expect("draw");
}

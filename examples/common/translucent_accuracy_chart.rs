//! `translucent_accuracy --chart`: relative L1 against patch count from the example's CSV.

use super::chart;

/// Relative L1 against patch count (log) in the CSV `csv`: the index-matched skin1 and marble
/// balls, today's defaults, the shape's solve with Lambert's exit, the flat profile (the
/// defaults before) and Bevy's best fit (every other row stays in the CSV and the docs' tables).
pub fn draw_chart(csv: &std::path::Path, path: &std::path::Path) -> Result<(), String> {
    const SCENES: [&str; 4] = [
        "ball_skin1_r10mm_front",
        "ball_marble_r10mm_front",
        "ball_skin1_r10mm_back",
        "ball_marble_r10mm_back",
    ];
    const METHODS: [&str; 4] = [
        "patches_scaleddipole",
        "patches_scaleddipole_lambert",
        "patches_scaleddipole_flat_lambert",
        "bevy_diffuse_transmission",
    ];
    use plotters::prelude::*;
    let text = std::fs::read_to_string(csv)
        .map_err(|e| format!("cannot read {}: {e}", csv.display()))?;
    let mut series: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    let mut levels: Vec<(String, f64)> = Vec::new();
    for line in text.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let (Some(scene), Some(method), Some(rel)) = (
            f.first(),
            f.get(1),
            f.get(9).and_then(|v| v.parse::<f64>().ok()),
        ) else {
            continue;
        };
        if !SCENES.contains(scene) || !METHODS.contains(method) {
            continue;
        }
        let key = format!("{scene} {method}");
        match f.get(3).and_then(|v| v.parse::<f64>().ok()) {
            Some(patches) => match series.iter_mut().find(|s| s.0 == key) {
                Some(s) => s.1.push((patches.log10(), rel)),
                None => series.push((key, vec![(patches.log10(), rel)])),
            },
            None => levels.push((key, rel)),
        }
    }
    for s in &mut series {
        s.1.sort_by(|a, b| a.0.total_cmp(&b.0));
    }
    chart::save(1400, 600, path, |root| {
        let panels = root.split_evenly((1, 2));
        for (panel, (which, title)) in panels.iter().zip([
            ("_front", "lit from the front"),
            ("_back", "lit from behind"),
        ]) {
            let shown: Vec<&(String, Vec<(f64, f64)>)> =
                series.iter().filter(|s| s.0.contains(which)).collect();
            let flat: Vec<&(String, f64)> = levels.iter().filter(|l| l.0.contains(which)).collect();
            let top = shown
                .iter()
                .flat_map(|s| s.1.iter().map(|p| p.1))
                .chain(flat.iter().map(|l| l.1))
                .fold(0.1, f64::max);
            let mut c = ChartBuilder::on(panel)
                .caption(
                    format!("1 cm ball against the light-traced reference, {title}"),
                    ("sans-serif", 18),
                )
                .margin(12)
                .x_label_area_size(40)
                .y_label_area_size(56)
                .build_cartesian_2d(
                    2.0f64..3.8f64,
                    0.0f64..top * if which == "_front" { 2.4 } else { 1.3 },
                )
                .expect("draw");
            c.configure_mesh()
                .x_desc("patches on the ball")
                .y_desc("relative L1 (all channels)")
                .x_label_formatter(&|x| format!("{:.0}", 10f64.powf(*x)))
                .label_style(("sans-serif", 13))
                .draw()
                .expect("draw");
            for (i, (label, points)) in shown.iter().map(|s| (&s.0, &s.1)).enumerate() {
                let colour = Palette99::pick(i).to_rgba();
                chart::line_with_points(&mut c, &label.replace("ball_", ""), points, colour);
            }
            for (i, (label, level)) in flat.iter().map(|l| (&l.0, l.1)).enumerate() {
                let colour = Palette99::pick(shown.len() + i).to_rgba();
                c.draw_series(DashedLineSeries::new(
                    [(2.0, level), (3.8, level)],
                    8,
                    6,
                    colour.stroke_width(2),
                ))
                .expect("draw")
                .label(format!("{} (best fit)", label.replace("ball_", "")))
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], colour));
            }
            // The goal.
            c.draw_series(DashedLineSeries::new(
                [(2.0, 0.08), (3.8, 0.08)],
                3,
                3,
                BLACK.stroke_width(1),
            ))
            .expect("draw")
            .label("goal 0.08")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK));
            // Where the data is not: above the front-lit curves; left of the back-lit ones
            // (scored at 960 and 1660 patches only).
            chart::legend_at(
                &mut c,
                if which == "_front" {
                    SeriesLabelPosition::UpperRight
                } else {
                    SeriesLabelPosition::UpperLeft
                },
            );
        }
    });
    println!("wrote {}", path.display());
    Ok(())
}

//! Earlier runs' rows (`--from`) and the speed/accuracy chart.

use super::*;

/// The rows of earlier runs' CSVs (`--from`), and their picture size.
pub(crate) fn read_rows(files: &[PathBuf], size: &mut u32) -> Vec<Row> {
    let mut rows = vec![];
    for file in files {
        let text = std::fs::read_to_string(file).unwrap_or_else(|e| {
            common::fail(format!("--from {}: cannot read it: {e}", file.display()))
        });
        for line in text.lines().skip(1).filter(|l| !l.is_empty()) {
            let f: Vec<&str> = line.split(',').collect();
            let width = f.get(3).and_then(|w| w.parse().ok());
            let (11, Some(width)) = (f.len(), width) else {
                common::fail(format!("--from {}: not an accuracy row: {line}", file.display()))
            };
            let num = |i: usize| -> f32 { f[i].parse().unwrap_or(f32::NAN) };
            *size = width;
            rows.push(Row {
                scene: f[0].into(),
                method: f[1].into(),
                setting: f[2].into(),
                gpu_ms: num(5) as f64,
                ao: (num(6), num(7)),
                shadow: num(8),
                bounce: num(9),
                flip: num(10),
            });
        }
    }
    rows
}

/// Mean over the scenes of each (method, setting): GPU time against AO MAE (left) and against
/// the mean FLIP of the shaded picture (right).
pub(crate) fn draw_chart(rows: &[Row], path: &PathBuf) {
    use plotters::prelude::*;
    let series_of = |metric: &dyn Fn(&Row) -> f64| {
        let mut series: Vec<(&str, Vec<(f64, f64)>)> = vec![];
        for method in ["none", "bevy-ssao", "horizon-search", "mesostructure"] {
            let mut settings: Vec<&String> = rows
                .iter()
                .filter(|r| r.method == method)
                .map(|r| &r.setting)
                .collect();
            settings.sort();
            settings.dedup();
            let mut points = vec![];
            for s in settings {
                let of: Vec<&Row> = rows
                    .iter()
                    .filter(|r| r.method == method && &r.setting == s)
                    .collect();
                let n = of.len() as f64;
                points.push((
                    of.iter().map(|r| r.gpu_ms).sum::<f64>() / n,
                    of.iter().map(|r| metric(r)).sum::<f64>() / n,
                ));
            }
            points.sort_by(|a, b| a.0.total_cmp(&b.0));
            series.push((method, points));
        }
        series
    };
    common::chart::save(1400, 520, path, |root| {
        let panels = root.split_evenly((1, 2));
        let metrics: [(&str, &str, &dyn Fn(&Row) -> f64); 2] = [
            (
                "Ambient occlusion: GPU time against error",
                "AO mean absolute error",
                &|r: &Row| r.ao.0 as f64,
            ),
            (
                "Shaded picture: GPU time against FLIP",
                "mean FLIP error",
                &|r: &Row| r.flip as f64,
            ),
        ];
        for (panel, (caption, y_desc, metric)) in panels.iter().zip(metrics) {
            let series = series_of(metric);
            let max_x = series
                .iter()
                .flat_map(|(_, p)| p.iter().map(|q| q.0))
                .fold(1e-3, f64::max)
                * 1.1;
            let max_y = series
                .iter()
                .flat_map(|(_, p)| p.iter().map(|q| q.1))
                .fold(1e-3, f64::max)
                * 1.1;
            let mut chart = ChartBuilder::on(panel)
                .caption(caption, ("sans-serif", 20))
                .margin(15)
                .x_label_area_size(45)
                .y_label_area_size(60)
                .build_cartesian_2d(0.0..max_x, 0.0..max_y)
                .expect("draw");
            chart
                .configure_mesh()
                .x_desc("GPU time of the added passes, ms (mean over scenes)")
                .y_desc(y_desc)
                .label_style(("sans-serif", 14))
                .draw()
                .expect("draw");
            for (i, (method, points)) in series.iter().enumerate() {
                let color = [BLACK, BLUE, GREEN, RED][i % 4].to_rgba();
                common::chart::line_with_points(&mut chart, method, points, color);
            }
            common::chart::legend(&mut chart);
        }
    });
}

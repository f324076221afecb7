//! `--suite unseen`: the unseen-content suite (`examples/common/unseen/`) as this example
//! runs it.

use super::*;

/// The settings a `--variants` name stands for.
pub(crate) fn variant_settings(name: &str) -> Option<common::unseen::Variant> {
    if let Some(quality) = MesostructureQuality::from_name(name) {
        return Some(Mesostructure { quality, ..default() }.into());
    }
    let (key, value) = name.split_once('=').unwrap_or((name, ""));
    let n = value.parse::<u32>().ok();
    let custom = |change: &dyn Fn(&mut MesostructureCost)| Mesostructure {
        quality: MesostructureQuality::High.custom(change),
        ..default()
    };
    Some(
        match key {
            "search" => {
                return Some(common::unseen::Variant {
                    settings: Mesostructure::default(),
                    baseline: Some(HorizonSearchBaseline { steps: n? }),
                });
            }
            "radius" => {
                let n = n?;
                custom(&|c| c.max_sample_radius = n)
            }
            "directions" => {
                let n = n?;
                custom(&|c| c.apex_directions = n)
            }
            "steps" => {
                let n = n?;
                custom(&|c| c.max_ascent_steps = n)
            }
            "samples" => {
                let n = n?;
                custom(&|c| c.bleeding_samples = n)
            }
            "softness" => Mesostructure {
                micro_shadow_softness: value.parse().ok()?,
                ..default()
            },
            "no-coarse" => Mesostructure {
                coarse_occlusion: false,
                ..default()
            },
            "screen-space" => Mesostructure {
                texture_space_horizons: false,
                ..default()
            },
            "no-texture-bounce" => Mesostructure {
                texture_space_bounce: false,
                ..default()
            },
            _ => return None,
        }
        .into(),
    )
}

/// The unseen-content suite (`--suite unseen`): per scene, the plugin at its defaults and no
/// effect against the ray-cast truth of the displaced mesh; a CSV and a Markdown table.
pub(crate) fn run_unseen(args: &Args) {
    use common::unseen;
    let out = args.out.clone().unwrap_or_else(|| "out/accuracy-unseen.csv".into());
    let size = args.size.unwrap_or(128);
    let mut scenes = unseen::scenes();
    if let Some(keep) = &args.scenes {
        scenes.retain(|s| keep.split(',').any(|k| s.name.contains(k)));
    }
    if scenes.is_empty() {
        common::fail(format!("no scene matches --scenes {}", args.scenes.as_deref().unwrap_or("")));
    }
    let unit = unseen::radiance_unit(common::headless_plugins(), size);
    println!("radiance unit ρE0/π = {unit:.5}");
    let mut csv = String::from(
        "scene,core,map,view,light,method,setting,width,height,texels_per_px,pixels,facing,gpu_ms,\
         ao_mae,ao_bias,shadow_recall,shadow_precision,bounce_rel_mae,bounce_ratio\n",
    );
    let mut table = String::from(
        "| scene | texels/px | AO MAE (none) | AO MAE | AO bias | shadow recall | shadow precision | bounce rel. MAE | bounce ratio |\n|---|---|---|---|---|---|---|---|---|\n",
    );
    for scene in &scenes {
        println!("accuracy: {}", scene.name);
        for variant in &args.variants {
        let Some(settings) = variant_settings(variant) else {
            common::fail(format!("unknown --variants entry {variant:?}"));
        };
        let Some(r) = unseen::run_scene(
            common::headless_plugins,
            scene,
            settings,
            size,
            args.step,
            unit,
            16,
        ) else {
            eprintln!("  {}: nothing rendered, skipped", scene.name);
            continue;
        };
        println!(
            "  truth {:.1} s; AO MAE {:.4} (none {:.4}), bias {:+.4}; shadows recall {:.3} precision {:.3}; \
             bounce rel. MAE {:.3} ratio {:.3}",
            r.truth_seconds,
            r.plugin.ao_mae,
            r.none.ao_mae,
            r.plugin.ao_bias,
            r.plugin.shadow_recall,
            r.plugin.shadow_precision,
            r.plugin.bounce_rel_mae,
            r.plugin.bounce_ratio
        );
        for (method, setting, s, ms) in [
            ("none", "-", &r.none, 0.0),
            ("mesostructure", variant.as_str(), &r.plugin, r.gpu_ms),
        ] {
            let _ = writeln!(
                csv,
                "{},{},{},{},{},{method},{setting},{size},{size},{:.2},{},{},{ms:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4}",
                scene.name,
                scene.core.name(),
                scene.map,
                scene.view,
                scene.light_elevation,
                s.texels_per_pixel,
                s.pixels,
                s.facing,
                s.ao_mae,
                s.ao_bias,
                s.shadow_recall,
                s.shadow_precision,
                s.bounce_rel_mae,
                s.bounce_ratio
            );
        }
        let p = &r.plugin;
        let _ = writeln!(
            table,
            "| {} {variant} | {:.2} | {:.3} | {:.3} | {:+.3} | {:.2} | {:.2} | {:.2} | {:.2} |",
            scene.name,
            p.texels_per_pixel,
            r.none.ao_mae,
            p.ao_mae,
            p.ao_bias,
            p.shadow_recall,
            p.shadow_precision,
            p.bounce_rel_mae,
            p.bounce_ratio
        );
        }
    }
    if let Some(dir) = out.parent() {
        std::fs::create_dir_all(dir).expect("cannot create the output folder");
    }
    std::fs::write(&out, csv).expect("cannot write the CSV");
    println!("{table}");
    println!("wrote {}", out.display());
}

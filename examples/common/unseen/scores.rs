//! The unseen-content suite's scores: AO error and bias, micro-shadow recall and precision,
//! the bounce's relative error, from the truths and one method's estimates.

use super::*;

/// The scores of one method on one scene.
#[derive(Clone, Debug, Default)]
pub struct Scores {
    pub ao_mae: f32,
    pub ao_bias: f32,
    pub shadow_recall: f32,
    pub shadow_precision: f32,
    pub bounce_rel_mae: f32,
    pub bounce_ratio: f32,
    /// Pixels scored, and of them light-facing ones with a core in the light.
    pub pixels: usize,
    pub facing: usize,
    /// Median height-map texels per pixel.
    pub texels_per_pixel: f32,
}

/// What a method says at one pixel.
#[derive(Clone, Copy, Debug)]
pub struct Estimate {
    pub ao: f32,
    pub shadowed: bool,
    pub bounce: f32,
}

/// Scores `estimates` against `truths` (same pixels).
pub fn score(truths: &[Truth], estimates: &[Estimate], texels_per_pixel: f32) -> Scores {
    let n = truths.len().max(1) as f32;
    let ao_mae = truths.iter().zip(estimates).map(|(t, e)| (e.ao - t.ao).abs()).sum::<f32>() / n;
    let ao_bias = truths.iter().zip(estimates).map(|(t, e)| e.ao - t.ao).sum::<f32>() / n;
    let (mut tp, mut fp, mut fne, mut facing) = (0.0f32, 0.0f32, 0.0f32, 0);
    for (t, e) in truths.iter().zip(estimates) {
        if !t.facing || t.core_shadowed {
            continue;
        }
        facing += 1;
        match (!t.lit, e.shadowed) {
            (true, true) => tp += 1.0,
            (false, true) => fp += 1.0,
            (true, false) => fne += 1.0,
            _ => {}
        }
    }
    let truth_bounce: f32 = truths.iter().map(|t| t.bounce).sum();
    let bounce_err: f32 = truths.iter().zip(estimates).map(|(t, e)| (e.bounce - t.bounce).abs()).sum();
    let bounce_sum: f32 = estimates.iter().map(|e| e.bounce).sum();
    Scores {
        ao_mae,
        ao_bias,
        // Recall with no shadowed pixel in the truth is vacuous: 1.
        shadow_recall: if tp + fne > 0.0 { tp / (tp + fne) } else { 1.0 },
        shadow_precision: if tp + fp > 0.0 { tp / (tp + fp) } else { 1.0 },
        bounce_rel_mae: bounce_err / truth_bounce.max(1e-6),
        bounce_ratio: bounce_sum / truth_bounce.max(1e-6),
        pixels: truths.len(),
        facing,
        texels_per_pixel,
    }
}

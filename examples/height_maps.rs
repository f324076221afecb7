//! Writes the built-in height maps as 8-bit grey PNGs under `assets/height_maps/`, and the stone
//! map in every format the plugin reads from files (8-bit and 16-bit grey PNG, 32-bit float
//! EXR) under `assets/height_maps/formats/`, which the tests load.
//!
//! ```text
//! cargo run --example height_maps [-- SIZE]
//! ```

use bevy_mesostructure::height_maps::HeightMap;
use image::{DynamicImage, ImageBuffer, Luma, Rgb};

/// Writes the built-in height maps as PNGs, and the stone map in every file format the tests load.
#[derive(clap::Parser)]
#[command(long_about = None)]
struct Cli {
    /// Side of the square maps, texels
    #[arg(default_value_t = 512, value_parser = clap::value_parser!(u32).range(8..=8192))]
    size: u32,
}

fn main() {
    use clap::Parser;
    let size = Cli::parse().size;
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/height_maps");
    std::fs::create_dir_all(dir.join("formats")).expect("cannot create assets/height_maps");
    for name in HeightMap::NAMES {
        let map = HeightMap::by_name(name, size).expect("a known name");
        let image = map
            .to_image_gray8()
            .try_into_dynamic()
            .expect("R8Unorm converts");
        let path = dir.join(format!("{name}.png"));
        image.save(&path).expect("cannot write the PNG");
        println!("wrote {}", path.display());
    }
    // The same map three ways, small (the tests render it at 64²).
    let map = HeightMap::by_name("stone", 128).expect("stone");
    let (w, h) = (map.width, map.height);
    let files: [(&str, DynamicImage); 3] = [
        (
            "stone_8bit.png",
            DynamicImage::ImageLuma8(ImageBuffer::from_fn(w, h, |x, y| {
                Luma([(map.values[(y * w + x) as usize] * 255.0).round() as u8])
            })),
        ),
        (
            "stone_16bit.png",
            DynamicImage::ImageLuma16(ImageBuffer::from_fn(w, h, |x, y| {
                Luma([(map.values[(y * w + x) as usize] * 65535.0).round() as u16])
            })),
        ),
        (
            "stone_float.exr",
            DynamicImage::ImageRgb32F(ImageBuffer::from_fn(w, h, |x, y| {
                let v = map.values[(y * w + x) as usize];
                Rgb([v, v, v])
            })),
        ),
    ];
    for (file, image) in files {
        let path = dir.join("formats").join(file);
        image.save(&path).expect("cannot write the file");
        println!("wrote {}", path.display());
    }
}

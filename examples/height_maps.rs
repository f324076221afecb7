//! Writes the built-in height maps as 8-bit grey PNGs under `assets/height_maps/`.
//!
//! ```text
//! cargo run --example height_maps [-- SIZE]
//! ```

use bevy_mesostructure::height_maps::HeightMap;

fn main() {
    let size: u32 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(512);
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/height_maps");
    std::fs::create_dir_all(&dir).expect("cannot create assets/height_maps");
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
}

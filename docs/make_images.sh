#!/usr/bin/env bash
# Re-makes every picture in docs/images/ with the examples (headless; the windowed one needs a
# display, e.g. `xvfb-run -a bash docs/make_images.sh`). Run from the repository root.
set -euo pipefail
out=out/images
rm -rf "$out"
run() { cargo run -q --example "$@" 2>&1 | grep '^wrote' || true; }

# The README's headline: the sphere→cube morph, and every debug view of bricks on a plane and
# on the sphere.
run deforming -- --frames 40 --view none --out "$out/morph" --headless
cp "$out/morph/morph_none.png" docs/images/morph_lit.png
run deforming -- --shape plane --view all --frames 8 --out "$out/plane" --headless
run deforming -- --shape sphere --view all --frames 8 --out "$out/sphere" --headless
for v in height apex-distance occlusion; do cp "$out/plane/plane_$v.png" "docs/images/plane_$v.png"; done
for v in gradient apex-count boundary occlusion; do cp "$out/sphere/sphere_$v.png" "docs/images/sphere_$v.png"; done

# Each effect on and off, bricks and rivets, light low from the side.
for map in bricks rivets; do
  for off in "" occlusion micro-shadows bleeding; do
    run deforming -- --shape plane --height-map "$map" --view none --light-height 1.2 \
      --frames 8 --out "$out/$map" --headless ${off:+--off $off}
  done
  for view in micro-shadow bleeding; do
    run deforming -- --shape plane --height-map "$map" --view "$view" --light-height 1.2 \
      --frames 8 --out "$out/$map" --headless
  done
  cp "$out/$map/plane_none.png" "docs/images/${map}_lit.png"
  for e in occlusion micro-shadows bleeding; do
    cp "$out/$map/plane_no-${e}_none.png" "docs/images/${map}_no-$e.png"
  done
  cp "$out/$map/plane_micro-shadow.png" "docs/images/${map}_micro-shadow.png"
  cp "$out/$map/plane_bleeding.png" "docs/images/${map}_bleeding.png"
done

# Gallery and comparison.
run gallery -- --frames 10 --out "$out/gallery" --headless
cp "$out/gallery/gallery_none.png" docs/images/gallery.png
run compare -- --frames 10 --out "$out/compare" --headless
cp "$out"/compare/compare_*.png docs/images/

# Unseen content: a torus with the photo-derived pebbles, the paper's screen-space terms against
# the texture-space horizons (README).
for v in before now; do
  flag=""; [ "$v" = before ] && flag="--screen-space"
  run render -- --mesh torus --height-map assets/height_maps/photo/pebbles.png --scale 0.05 \
    --tiles 6,2 --eye 0,1.3,1.7 --light-dir 1,-0.3,-0.4 --size 384x288 $flag --out "$out/torus_$v.png"
done
python3 -c "
from PIL import Image
a, b = Image.open('$out/torus_before.png'), Image.open('$out/torus_now.png')
s = Image.new('RGB', (a.width * 2 + 8, a.height), (255, 255, 255))
s.paste(a, (0, 0)); s.paste(b, (a.width + 8, 0)); s.save('docs/images/unseen_torus.png')"

# The window with the tuning panel (needs a display).
if [ -n "${DISPLAY:-}${WAYLAND_DISPLAY:-}" ]; then
  run deforming -- --frames 20 --view none --out "$out/window"
  cp "$out/window/morph_none.png" docs/images/deforming_window.png
fi

# Volumetric spots: the dark room with and without the haze.
run volumetric_spots -- --frames 20 --out "$out/volumetric" --headless
cp "$out/volumetric/volumetric_spots.png" docs/images/volumetric_spots.png
cp "$out/volumetric/volumetric_spots_no-haze.png" docs/images/volumetric_spots_no-haze.png

# Translucent objects (seed 001): lit from the front, from behind, and from behind as Bevy
# shades it without the transport.
run translucent -- --out "$out/translucent" --size 384x288 --headless
cp "$out"/translucent/translucent_*.png docs/images/

# Translucency charts (the accuracy one from docs/translucent.csv; needs `pip install mitsuba
# numpy` for the references): see docs/translucent.md for the full commands.
run translucent_precompute -- --budgets 500,1000,2000,5000,10000,20000 \
  --out docs/translucent-precompute.csv --chart docs/images/translucent_precompute.png

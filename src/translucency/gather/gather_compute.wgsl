// Seed 001's gather in compute (`gathered.wgsl` holds what it shares with the fragment
// form, `gather.wgsl`), where the view's main images take storage writes: a pass writing lit +
// gathered into the view's other main image (`gather_compute`), whose 8×8 tiles walk the grids
// once for their pixels (`collect_tile_patches`), or (HALF_RESOLUTION) the same at one pixel
// in 2×2 and the rest upsampled from the samples on their own surface (`gather_half`,
// `gather_upsample`, `gather_unserved`).

#import bevy_mesostructure::translucency::boundary::{from_ordered_bits, ordered_bits}
#import bevy_mesostructure::translucency::gathered::{
    add_patch, bucket, depth_prepass, finish, Gathered, gathered, grid, grid_level, GridLevel,
    member_in_cell, no_light, no_surface, params, patches, pixel_surface, Surface, view, walked,
}

// The lit image and the image written (Bevy's post-process ping-pong): every pixel is copied,
// with the gathered light added where there is some; alpha kept.
@group(0) @binding(7) var lit: texture_2d<f32>;
@group(0) @binding(8) var lit_out: texture_storage_2d<rgba16float, write>;

// The surface the view's pixel `id` shows; none outside the view.
fn view_surface(id: vec2<u32>) -> Surface {
    if any(id >= textureDimensions(lit)) {
        return no_surface();
    }
    return pixel_surface(vec2<i32>(id), vec2<f32>(id) + 0.5);
}

// A workgroup's 8×8 pixels walk the grids once together (tiled culling, as Forward+ does for
// lights): the cells about the box of their world points give the patches that reach the
// box, and each pixel then takes its own from that list — instead of each pixel hashing its
// own 27 cells a grid and walking their buckets, out of step with its neighbours. A tile
// whose box spans more than `TILE_CELLS` cells of a grid or reaches more than `TILE_PATCHES`
// patches (an outline over what lies behind it) tries again as two: its pixels nearer and
// farther than the middle of their distances from the camera, a list each. Those still too
// large walk the grids pixel by pixel as the fragment form does (on an H100 at 1080p, half
// resolution, those walks were 40 % of the gather's first pass before the split).
const TILE_PATCHES: u32 = 256u;
const TILE_CELLS: u32 = 128u;

// The tile's box and its pixels' distances from the camera as order-preserving bits (least
// x y z distance, most x y z distance).
var<workgroup> tile_box: array<atomic<u32>, 8>;
var<workgroup> tile_count: atomic<u32>;
var<workgroup> tile_patches: array<u32, TILE_PATCHES>;
var<workgroup> tile_listed: u32;

// The cells of grid `g` about the box [lo, hi]: a grid's cells are as wide as its widest
// reach, so a patch reaching the box has its centre in the box grown by one cell (and a
// little, for rounding).
struct CellRange {
    first: vec3<i32>,
    extent: vec3<u32>,
}

fn cells_about(g: GridLevel, lo: vec3<f32>, hi: vec3<f32>) -> CellRange {
    let first = vec3<i32>(floor(lo / g.cell_size - 1.001));
    let last = vec3<i32>(floor(hi / g.cell_size + 1.001));
    return CellRange(first, vec3<u32>(last - first + 1));
}

// Whether the box [lo, hi] spans at most `TILE_CELLS` cells in every grid (each extent first:
// their product could wrap).
fn box_fits(lo: vec3<f32>, hi: vec3<f32>) -> bool {
    for (var level = 0u; level < params.levels; level += 1u) {
        let e = cells_about(grid_level(level), lo, hi).extent;
        if any(e > vec3(TILE_CELLS)) || e.x * e.y * e.z > TILE_CELLS {
            return false;
        }
    }
    return true;
}

// The patches of all grids that may reach the box [lo, hi] (which `box_fits`) into
// `tile_patches`, the cells shared among the workgroup's threads (`thread` of 64).
fn collect_tile_patches(thread: u32, lo: vec3<f32>, hi: vec3<f32>) {
    for (var level = 0u; level < params.levels; level += 1u) {
        let g = grid_level(level);
        let range = cells_about(g, lo, hi);
        let extent = range.extent;
        let cells = extent.x * extent.y * extent.z;
        for (var c = thread; c < cells; c += 64u) {
            let cell = range.first + vec3<i32>(vec3(c % extent.x, (c / extent.x) % extent.y, c / (extent.x * extent.y)));
            let b = bucket(cell, g.mask);
            for (var k = grid[g.table + b]; k < grid[g.table + b + 1u]; k += 1u) {
                let member = member_in_cell(g, k, cell);
                if member < 0 {
                    continue;
                }
                let i = u32(member);
                let centre = patches[i].centre;
                // The patch's distance from the box, against its reach (a little grown: the
                // pixels' own test decides).
                let out = max(max(lo - centre.xyz, centre.xyz - hi), vec3(0.0));
                if dot(out, out) >= centre.w * centre.w * 1.0001 {
                    continue;
                }
                let slot = atomicAdd(&tile_count, 1u);
                if slot < TILE_PATCHES {
                    tile_patches[slot] = i;
                }
            }
        }
    }
}

// A box of some of the tile's pixels, and their least and most distance from the camera.
struct TileBox {
    // Some pixel took part.
    any: bool,
    lo: vec3<f32>,
    hi: vec3<f32>,
    near: f32,
    far: f32,
}

// The box of the pixels whose `member` is true (`s` their surfaces, `d` their distances from
// the camera). Every thread of the workgroup calls it (it holds barriers); all get the same
// box.
fn tile_box_of(thread: u32, s: Surface, d: f32, member: bool) -> TileBox {
    if thread == 0u {
        for (var k = 0u; k < 4u; k += 1u) {
            atomicStore(&tile_box[k], 0xffffffffu);
            atomicStore(&tile_box[4u + k], 0u);
        }
    }
    workgroupBarrier();
    if member {
        atomicMin(&tile_box[0], ordered_bits(s.x.x));
        atomicMin(&tile_box[1], ordered_bits(s.x.y));
        atomicMin(&tile_box[2], ordered_bits(s.x.z));
        atomicMin(&tile_box[3], ordered_bits(d));
        atomicMax(&tile_box[4], ordered_bits(s.x.x));
        atomicMax(&tile_box[5], ordered_bits(s.x.y));
        atomicMax(&tile_box[6], ordered_bits(s.x.z));
        atomicMax(&tile_box[7], ordered_bits(d));
    }
    workgroupBarrier();
    let lo = vec3(atomicLoad(&tile_box[0]), atomicLoad(&tile_box[1]), atomicLoad(&tile_box[2]));
    let hi = vec3(atomicLoad(&tile_box[4]), atomicLoad(&tile_box[5]), atomicLoad(&tile_box[6]));
    let near = atomicLoad(&tile_box[3]);
    let far = atomicLoad(&tile_box[7]);
    // Every thread has read the box before it is reset again.
    workgroupBarrier();
    return TileBox(
        all(lo <= hi),
        vec3(from_ordered_bits(lo.x), from_ordered_bits(lo.y), from_ordered_bits(lo.z)),
        vec3(from_ordered_bits(hi.x), from_ordered_bits(hi.y), from_ordered_bits(hi.z)),
        from_ordered_bits(near),
        from_ordered_bits(far),
    );
}

// The list of the patches that may reach `box` into `tile_patches`: whether it holds them all
// (the box spans few enough cells and they are few enough), the same in every thread. Every
// thread of the workgroup calls it (it holds barriers).
fn tile_list(thread: u32, box: TileBox) -> bool {
    if thread == 0u {
        atomicStore(&tile_count, 0u);
    }
    workgroupBarrier();
    let fits = box.any && box_fits(box.lo, box.hi);
    if fits {
        collect_tile_patches(thread, box.lo, box.hi);
    }
    workgroupBarrier();
    if thread == 0u {
        tile_listed = select(0u, 1u, fits && atomicLoad(&tile_count) <= TILE_PATCHES);
    }
    return workgroupUniformLoad(&tile_listed) == 1u;
}

// The sums of a pixel (`s`) from the list, or where the list does not hold its patches
// (`listed` false) from its own walk of the grids.
fn listed_or_walked(s: Surface, listed: bool) -> Gathered {
    if !listed {
        return walked(s);
    }
    var acc = no_light();
    let count = atomicLoad(&tile_count);
    for (var k = 0u; k < count; k += 1u) {
        add_patch(tile_patches[k], s, &acc);
    }
    return acc;
}

// The sums for each thread's surface `s` (invalid: none wanted) by the tile's walk of the
// grids. Every thread of the workgroup calls it (it holds barriers).
fn tile_walked(thread: u32, s: Surface) -> Gathered {
    var acc = no_light();
    // Each pixel's distance from the camera, once for the tile's boxes and its side.
    let d = distance(s.x, view.world_position);
    let whole = tile_box_of(thread, s, d, s.valid);
    if tile_list(thread, whole) {
        if s.valid {
            acc = listed_or_walked(s, true);
        }
        return acc;
    }
    // Too large for one list: the pixels nearer than the middle of the tile's distances, then
    // the farther ones, a list each.
    let middle = 0.5 * (whole.near + whole.far);
    let far_side = s.valid && d > middle;
    for (var side = 0u; side < 2u; side += 1u) {
        let member = s.valid && far_side == (side == 1u);
        let listed = tile_list(thread, tile_box_of(thread, s, d, member));
        if member {
            acc = listed_or_walked(s, listed);
        }
        // Every pixel of this side is done with the list before the next side's.
        workgroupBarrier();
    }
    return acc;
}

#ifdef HALF_RESOLUTION
// `GatherResolution::Half`: the tiled gather at one pixel in 2×2 (`gather_half`, into
// `half_light`), then every pixel of the view from the four samples about it whose surface is
// its own (`gather_upsample`), and last the pixels none of them serves (at a depth edge or a
// crease), which gather themselves as the full-resolution gather does (`gather_unserved`, its
// own pass so that the upsample keeps the few registers it needs; only the tiles that hold such
// a pixel work).

// Per sample (the top-left pixel of its 2×2): the gathered light times the exposure, and in
// w the smallest reach of the patches that reached it, -1 where none reached its surface, 0
// where it shows none.
@group(0) @binding(9) var half_light_out: texture_storage_2d<rgba32float, write>;
@group(0) @binding(10) var half_light: texture_2d<f32>;
// Per 8×8 tile, 1 where some pixel of it is served by no sample.
@group(0) @binding(11) var unserved_tiles_out: texture_storage_2d<r32uint, write>;
@group(0) @binding(12) var unserved_tiles: texture_2d<u32>;

@compute @workgroup_size(8, 8, 1)
fn gather_half(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(local_invocation_index) thread: u32,
) {
    let inside = all(id.xy < textureDimensions(half_light_out));
    let p = vec2<i32>(2u * id.xy);
    var s = no_surface();
    if inside && all(vec2<u32>(p) < textureDimensions(depth_prepass)) {
        s = pixel_surface(p, vec2<f32>(p) + 0.5);
    }
    let acc = tile_walked(thread, s);
    if !inside {
        return;
    }
    var sample = vec4(0.0);
    if acc.weights > 0.0 {
        sample = vec4(finish(acc, s).rgb, acc.reach);
    } else if s.valid {
        sample = vec4(0.0, 0.0, 0.0, -1.0);
    }
    textureStore(half_light_out, id.xy, sample);
}

// Whether a sample's surface `r` (its light `sample`) is the pixel's surface `s`, seen alike:
// its normal within ~18° (0.95) and its exit cosine towards the camera within 0.05 (the exit
// law's limb darkening changes fast towards an outline), off the pixel's tangent plane by at
// most a quarter of their distance (a depth step is along the view ray, a curved surface's
// deviation second order), and, where patches reached it, within the smallest of their
// reaches (the light changes on that scale).
fn same_surface(s: Surface, r: Surface, sample: vec4<f32>) -> bool {
    if !r.valid || sample.w == 0.0 || dot(s.n, r.n) < 0.95 || abs(s.mu - r.mu) > 0.05 {
        return false;
    }
    let d = r.x - s.x;
    let d2 = dot(d, d);
    let off_plane = abs(dot(s.n, d));
    return off_plane * off_plane <= 0.0625 * d2 + 1.0e-12 && (sample.w < 0.0 || d2 <= sample.w * sample.w);
}

// The light of the samples about pixel `p` (surface `s`) that show its surface, weighted
// bilinearly; w: their weight, 0 where none serves it. The samples stand at the even pixels:
// an even coordinate is its own sample, an odd one halfway between two.
fn upsampled(p: vec2<i32>, s: Surface) -> vec4<f32> {
    var sum = vec3(0.0);
    var weight = 0.0;
    if s.valid {
        let base = p / 2;
        let t = vec2<f32>(p - 2 * base) * 0.5;
        let last = vec2<i32>(textureDimensions(half_light)) - 1;
        for (var k = 0u; k < 4u; k += 1u) {
            let c = vec2(i32(k & 1u), i32(k >> 1u));
            let bilinear = mix(1.0 - t.x, t.x, f32(c.x)) * mix(1.0 - t.y, t.y, f32(c.y));
            let q = base + c;
            if bilinear <= 0.0 || any(q > last) {
                continue;
            }
            let sample = textureLoad(half_light, q, 0);
            let r = pixel_surface(2 * q, vec2<f32>(2 * q) + 0.5);
            if same_surface(s, r, sample) {
                sum += bilinear * sample.rgb;
                weight += bilinear;
            }
        }
    }
    if weight <= 0.0 {
        return vec4(0.0);
    }
    return vec4(sum / weight, weight);
}

var<workgroup> tile_unserved: atomic<u32>;
var<workgroup> tile_unserved_uniform: u32;

@compute @workgroup_size(8, 8, 1)
fn gather_upsample(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(local_invocation_index) thread: u32,
    @builtin(workgroup_id) tile: vec3<u32>,
) {
    if thread == 0u {
        atomicStore(&tile_unserved, 0u);
    }
    workgroupBarrier();
    let inside = all(id.xy < textureDimensions(lit));
    let p = vec2<i32>(id.xy);
    let s = view_surface(id.xy);
    let added = upsampled(p, s);
    if s.valid && added.w <= 0.0 {
        atomicStore(&tile_unserved, 1u);
    }
    workgroupBarrier();
    if thread == 0u {
        textureStore(unserved_tiles_out, tile.xy, vec4(atomicLoad(&tile_unserved), 0u, 0u, 0u));
    }
    if !inside {
        return;
    }
    let colour = textureLoad(lit, p, 0);
    textureStore(lit_out, p, vec4(colour.rgb + added.rgb, colour.a));
}

@compute @workgroup_size(8, 8, 1)
fn gather_unserved(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(local_invocation_index) thread: u32,
    @builtin(workgroup_id) tile: vec3<u32>,
) {
    if thread == 0u {
        tile_unserved_uniform = textureLoad(unserved_tiles, tile.xy, 0).x;
    }
    if workgroupUniformLoad(&tile_unserved_uniform) == 0u {
        return;
    }
    let inside = all(id.xy < textureDimensions(lit));
    let p = vec2<i32>(id.xy);
    let s = view_surface(id.xy);
    let unserved = s.valid && upsampled(p, s).w <= 0.0;
    // The tile's box only about the pixels that gather themselves.
    var own = no_surface();
    if unserved {
        own = s;
    }
    let acc = tile_walked(thread, own);
    if unserved {
        let colour = textureLoad(lit, p, 0);
        textureStore(lit_out, p, vec4(colour.rgb + finish(acc, own).rgb, colour.a));
    }
}
#else
@compute @workgroup_size(8, 8, 1)
fn gather_compute(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(local_invocation_index) thread: u32,
) {
    let inside = all(id.xy < textureDimensions(lit));
    let p = vec2<i32>(id.xy);
    let s = view_surface(id.xy);
    let added = finish(tile_walked(thread, s), s);
    if !inside {
        return;
    }
    let colour = textureLoad(lit, p, 0);
    textureStore(lit_out, p, vec4(colour.rgb + added.rgb, colour.a));
}
#endif

// Compute pass of the energy: the twelve counts mask (none, own arch, other arch, mouth
// interior) x class (none, body, BOI) of each tile, the GPU form of the paper's white / pink /
// light-green / dark-green colour counting (which folds "other" and "mouth" into "none").
// The CPU twin is `count` in src/energy/histogram.rs.
//
// One workgroup covers a 32x32 block of one tile (tile `first_tile + workgroup_id.z`: a batch
// is rendered in atlas pages, one dispatch per page); each thread
// counts a 2x2 block privately, adds its non-zero counts to the workgroup's bins, and the
// first twelve threads add those to the tile's global bins once.

struct Tile {
    // Tile origin in the class atlas.
    atlas_x: u32,
    atlas_y: u32,
    width: u32,
    height: u32,
    // Origin of the tile in the camera's mask.
    mask_x: u32,
    mask_y: u32,
    // Mask texture layer (the camera), the scored arch's label bit and the other arch's.
    layer: u32,
    arch_bit: u32,
    other_bit: u32,
    // Where this tile's twelve counts go.
    slot: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<storage, read> tiles: array<Tile>;
@group(0) @binding(1) var<storage, read_write> counts: array<atomic<u32>>;
@group(0) @binding(2) var class_atlas: texture_2d<u32>;
@group(0) @binding(3) var masks: texture_2d_array<u32>;

struct Page {
    first_tile: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(4) var<uniform> page: Page;

const BLOCK: u32 = 32u;
const PER_THREAD: u32 = 2u;
const BINS: u32 = 12u;
// The mask's label bit of the visible mouth interior (src/capture/masks.rs).
const MOUTH_BIT: u32 = 4u;

var<workgroup> bins: array<atomic<u32>, 12>;

@compute @workgroup_size(16, 16, 1)
fn count(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_id) lid: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    if li < BINS {
        atomicStore(&bins[li], 0u);
    }
    workgroupBarrier();
    let t = tiles[page.first_tile + wg.z];
    var mine = array<u32, 12>();
    for (var dy = 0u; dy < PER_THREAD; dy++) {
        for (var dx = 0u; dx < PER_THREAD; dx++) {
            let x = wg.x * BLOCK + lid.x * PER_THREAD + dx;
            let y = wg.y * BLOCK + lid.y * PER_THREAD + dy;
            if x < t.width && y < t.height {
                let class_id = textureLoad(class_atlas, vec2<u32>(t.atlas_x + x, t.atlas_y + y), 0).r;
                let label = textureLoad(masks, vec2<u32>(t.mask_x + x, t.mask_y + y), t.layer, 0).r;
                // Own, else other, else mouth, else none (combined masks carry both arches'
                // bits: own), as `mask_state` in src/energy/mod.rs.
                let rest = select(select(0u, 3u, (label & MOUTH_BIT) != 0u), 2u, (label & t.other_bit) != 0u);
                let state = select(rest, 1u, (label & t.arch_bit) != 0u);
                mine[state * 3u + min(class_id, 2u)] += 1u;
            }
        }
    }
    for (var k = 0u; k < BINS; k++) {
        if mine[k] != 0u {
            atomicAdd(&bins[k], mine[k]);
        }
    }
    workgroupBarrier();
    if li < BINS {
        let v = atomicLoad(&bins[li]);
        if v != 0u {
            atomicAdd(&counts[t.slot * BINS + li], v);
        }
    }
}

// The smooth energy's edge terms, one thread per sample: the sample moved by its arch's
// increment looks along its normal for its arch's mask edge within the reach, and writes its
// offset, its least-squares weight and its share of the smooth energy. The CPU twin is
// src/energy/edge_terms.rs (`term`), line for line; the normal equations are summed on the
// CPU from either engine's terms, in a fixed order.

struct Sample {
    pixel: vec2<f32>,
    normal: vec2<f32>,
    // d(pixel)/d(increment), row-major 2 x 6.
    jacobian: array<f32, 12>,
    length: f32,
    view: u32,
    // 0: upper, 1: lower.
    arch: u32,
    // Bits: 1, a silhouette (else the BOI's edge where it meets the body); 2, the BOI just
    // inside it.
    kind: u32,
}

struct View {
    // The camera's mask layer and its size.
    layer: u32,
    width: u32,
    height: u32,
    _pad: u32,
}

struct Params {
    // Each arch's increment since the samples were drawn: upper in moved[0].xyzw, moved[1].xy;
    // lower in moved[1].zw, moved[2].xyzw.
    moved: array<vec4<f32>, 3>,
    reach: f32,
    smoothing: f32,
    lambda: f32,
    cross: f32,
    mouth: f32,
    count: u32,
    // The mask's label bits: upper arch, lower arch, mouth interior.
    upper_bit: u32,
    lower_bit: u32,
    mouth_bit: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<storage, read> samples: array<Sample>;
@group(0) @binding(1) var<storage, read> views: array<View>;
@group(0) @binding(2) var<uniform> params: Params;
@group(0) @binding(3) var masks: texture_2d_array<u32>;
// Per sample: offset, weight, energy, 1 where it has a term (else all 0).
@group(0) @binding(4) var<storage, read_write> terms: array<vec4<f32>>;
// How much of each pixel each arch's teeth hold (r upper, g lower): a mask's soft evidence,
// else its labels as 0 or 1.
@group(0) @binding(5) var evidence: texture_2d_array<f32>;

fn increment(arch: u32, k: u32) -> f32 {
    let i = arch * 6u + k;
    return params.moved[i / 4u][i % 4u];
}

fn label(view: View, i: i32, j: i32) -> u32 {
    if i < 0 || j < 0 || i >= i32(view.width) || j >= i32(view.height) {
        return 0u;
    }
    return textureLoad(masks, vec2<i32>(i, j), i32(view.layer), 0).r;
}

// How much of the pixel the arch's teeth hold (0 off the mask).
fn held(view: View, arch: u32, i: i32, j: i32) -> f32 {
    if i < 0 || j < 0 || i >= i32(view.width) || j >= i32(view.height) {
        return 0.0;
    }
    return textureLoad(evidence, vec2<i32>(i, j), i32(view.layer), 0)[arch];
}

// The arch's teeth at a position, bilinear between pixel centres (`label_read` of
// src/energy/edge_terms.rs).
fn on(view: View, arch: u32, x: vec2<f32>) -> f32 {
    let f = floor(x);
    let t = x - f;
    let i = i32(f.x);
    let j = i32(f.y);
    let a = held(view, arch, i, j);
    let b = held(view, arch, i + 1, j);
    let c = held(view, arch, i, j + 1);
    let d = held(view, arch, i + 1, j + 1);
    return (1.0 - t.y) * ((1.0 - t.x) * a + t.x * b) + t.y * ((1.0 - t.x) * c + t.x * d);
}

// Rust's `round`: half away from zero.
fn round_away(x: f32) -> f32 {
    return select(ceil(x - 0.5), floor(x + 0.5), x >= 0.0);
}

// `extra_read`: the cross-label weight over the other arch's label, the over-mouth weight
// over the mouth interior's, at the nearest pixel.
fn extra(view: View, own: u32, other: u32, x: vec2<f32>) -> f32 {
    let l = label(view, i32(round_away(x.x)), i32(round_away(x.y)));
    let cross = (l & other) != 0u && (l & own) == 0u;
    return select(0.0, params.cross, cross) + select(0.0, params.mouth, (l & params.mouth_bit) != 0u);
}

struct Offset {
    found: bool,
    d: f32,
}

// `edge_offset`: where the mask falls through one half, from inside to outside, nearest the
// sample within the reach.
fn edge_offset(view: View, arch: u32, p: vec2<f32>, n: vec2<f32>) -> Offset {
    let step = 0.5;
    let steps = u32(ceil(params.reach / step));
    var ahead = on(view, arch, p) - 0.5;
    var behind = ahead;
    for (var k = 0u; k < steps; k++) {
        let d0 = f32(k) * step;
        let d1 = f32(k + 1u) * step;
        let next_ahead = on(view, arch, p + d1 * n) - 0.5;
        let forward = ahead >= 0.0 && next_ahead < 0.0;
        let f = d0 + step * ahead / (ahead - next_ahead);
        let next_behind = on(view, arch, p - d1 * n) - 0.5;
        let backward = next_behind >= 0.0 && behind < 0.0;
        let b = -d1 + step * next_behind / (next_behind - behind);
        if forward && backward {
            return Offset(true, select(b, f, f <= -b));
        }
        if forward {
            return Offset(true, f);
        }
        if backward {
            return Offset(true, b);
        }
        ahead = next_ahead;
        behind = next_behind;
    }
    return Offset(false, 0.0);
}

// `loss`: Huber's parabola within the smoothing width, Tukey's biweight out to the reach,
// flat beyond.
fn tukey_integral(t: f32, r2: f32) -> f32 {
    return t - 2.0 * t * t * t / (3.0 * r2) + t * t * t * t * t / (5.0 * r2 * r2);
}

fn inner_integral(t: f32, eps: f32, r2: f32) -> f32 {
    let t2 = t * t;
    return t2 / (2.0 * eps) - t2 * t2 / (2.0 * eps * r2) + t2 * t2 * t2 / (6.0 * eps * r2 * r2);
}

fn loss(d: f32, smoothing: f32, reach: f32) -> f32 {
    let r2 = reach * reach;
    let eps = min(smoothing, reach);
    let a = min(abs(d), reach);
    if a < eps {
        return inner_integral(a, eps, r2);
    }
    return inner_integral(eps, eps, r2) + tukey_integral(a, r2) - tukey_integral(eps, r2);
}

@compute @workgroup_size(64, 1, 1)
fn edge_terms(@builtin(global_invocation_id) id: vec3<u32>) {
    let index = id.x;
    if index >= params.count {
        return;
    }
    let s = samples[index];
    terms[index] = vec4<f32>(0.0);
    var moved = s.pixel;
    for (var k = 0u; k < 6u; k++) {
        let m = increment(s.arch, k);
        moved += vec2<f32>(s.jacobian[k], s.jacobian[6u + k]) * m;
    }
    let view = views[s.view];
    let own = select(params.upper_bit, params.lower_bit, s.arch == 1u);
    let other = select(params.lower_bit, params.upper_bit, s.arch == 1u);
    let found = edge_offset(view, s.arch, moved, s.normal);
    if !found.found {
        return;
    }
    let d = found.d;
    // `cost`: past a silhouette, the model's pixels outside the mask; short of it, the mask's
    // pixels it leaves uncovered; past the BOI's edge, BOI outside the mask.
    let silhouette = (s.kind & 1u) != 0u;
    let boi = select(0.0, params.lambda, (s.kind & 2u) != 0u);
    var cost = 0.0;
    if !silhouette {
        cost = select(0.0, params.lambda, d < 0.0);
    } else if d < 0.0 {
        cost = extra(view, own, other, moved + 0.5 * d * s.normal) + boi;
    } else {
        cost = 1.0;
    }
    if cost == 0.0 {
        return;
    }
    let u = d / params.reach;
    let t = max(1.0 - u * u, 0.0);
    let tukey = t * t;
    let weight = cost * tukey * s.length / max(abs(d), params.smoothing);
    let energy = cost * s.length * loss(d, params.smoothing, params.reach);
    terms[index] = vec4<f32>(d, weight, energy, 1.0);
}

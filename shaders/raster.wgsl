// Render pass of the energy: each arch drawn at a candidate pose into a tile of the class
// atlas (R8Uint: 0 none, 1 body, 2 boundary of interest), depth-tested. The CPU twin is
// src/energy/raster.rs.
//
// The readback baseline's stages (shaders/readback.wgsl) are appended to this file: they draw
// with the same vertex stages.
//
// One `Draw` per draw call, selected by the instance index (draw_indexed's first instance).
//
// Pixel positions are those of the CPU twin: framebuffer coordinates u + 0.5 (OpenCV pixel
// centres at integers), snapped to 1/256 pixel. When every vertex of a draw is in front of the
// near plane (`projected`, checked on the CPU), the shader divides by z and snaps itself, and
// hands the rasteriser w = 1 positions on the 1/256 grid in a power-of-two viewport: the
// fixed-function viewport transform is then exact, whatever integer offset places the tile in
// the atlas. Otherwise positions stay homogeneous and the GPU clips at the near plane.
//
// A camera with a lens (OpenCV's model or the fisheye) has each vertex distorted before it is
// snapped (as the CPU twin does). A draw crossing the near plane is drawn without distortion: the clipping is the
// GPU's there, and the CPU's twin, which clips first, distorts the clipped polygon. Such poses
// put the arch within 1 mm of the camera.

const SUBPIXELS: f32 = 256.0;

struct Draw {
    camera_from_model: mat4x4<f32>,
    focal: vec2<f32>,
    // Framebuffer coordinates of the principal point: (cx + 0.5, cy + 0.5).
    centre: vec2<f32>,
    // Half the viewport's size (powers of two).
    half_viewport: vec2<f32>,
    near: f32,
    far: f32,
    class_id: u32,
    projected: u32,
    // Readback baseline only: mask pixel = framebuffer pixel − mask_offset, in `layer`, and
    // the scored arch's label bit.
    mask_offset: vec2<i32>,
    layer: u32,
    arch_bit: u32,
    _pad: vec2<u32>,
    // The camera's lens (src/energy/lens.rs): OpenCV's (k1, k2, p1, p2), (k3, k4, k5, k6),
    // (s1, s2, s3, s4), or the fisheye's (k1, k2, k3, k4) in `lens[0]`; the r² beyond which
    // points are not projected (the model folds back); the model: 0 none, 1 OpenCV, 2 fisheye.
    lens: array<vec4<f32>, 3>,
    lens_limit_r2: f32,
    lens_model: u32,
    _pad2: vec2<u32>,
}

@group(0) @binding(0) var<storage, read> draws: array<Draw>;
@group(0) @binding(1) var masks: texture_2d_array<u32>;

struct VsOut {
    // Invariant: the readback baseline's colour pass tests depth for equality with its
    // depth pre-pass, so both must compute identical positions.
    @builtin(position) @invariant position: vec4<f32>,
    @location(0) @interpolate(flat) class_id: u32,
    @location(1) @interpolate(flat) draw: u32,
}

// atan(r), r ≥ 0, from +, ×, ÷ alone, as src/energy/lens.rs computes it (the hardware's atan
// need not round as the CPU's does).
fn atan_twin(r: f32) -> f32 {
    var a = r;
    let flip = r > 1.0;
    if flip {
        a = 1.0 / r;
    }
    var u = a;
    var base = 0.0;
    if a > 0.41421357 {
        u = (a - 1.0) / (a + 1.0);
        base = 0.7853982;
    }
    let u2 = u * u;
    let series = u
        * (1.0
            + u2 * (-1.0 / 3.0
                + u2 * (1.0 / 5.0
                    + u2 * (-1.0 / 7.0
                        + u2 * (1.0 / 9.0
                            + u2 * (-1.0 / 11.0
                                + u2 * (1.0 / 13.0 + u2 * (-1.0 / 15.0 + u2 * (1.0 / 17.0)))))))));
    let t = base + series;
    if flip {
        return 1.5707964 - t;
    }
    return t;
}

// Distorted normalised coordinates, in the CPU's order of operations. Beyond the lens's limit
// the point is sent far outside the image (the CPU drops such triangles; they cannot reach the
// image either way while the limit lies outside it).
fn distort(d: Draw, n: vec2<f32>) -> vec2<f32> {
    let r2 = n.x * n.x + n.y * n.y;
    if r2 > d.lens_limit_r2 {
        return n * (1.0e3 / sqrt(r2));
    }
    let a = d.lens[0];
    if d.lens_model == 2u {
        if r2 < 1.0e-20 {
            return n;
        }
        let r = sqrt(r2);
        let t = atan_twin(r);
        let t2 = t * t;
        let s = t * (1.0 + t2 * (a.x + t2 * (a.y + t2 * (a.z + t2 * a.w)))) / r;
        return n * s;
    }
    let b = d.lens[1];
    let c = d.lens[2];
    // With k4..k6 zero the quotient is by 1.0, exact: the classic model's bits.
    let radial = (1.0 + r2 * (a.x + r2 * (a.y + r2 * b.x))) / (1.0 + r2 * (b.y + r2 * (b.z + r2 * b.w)));
    let xy = n.x * n.y;
    return vec2<f32>(
        n.x * radial + 2.0 * a.z * xy + a.w * (r2 + 2.0 * n.x * n.x) + r2 * (c.x + r2 * c.y),
        n.y * radial + a.z * (r2 + 2.0 * n.y * n.y) + 2.0 * a.w * xy + r2 * (c.z + r2 * c.w),
    );
}

@vertex
fn vs_model(@location(0) position: vec3<f32>, @builtin(instance_index) draw: u32) -> VsOut {
    let d = draws[draw];
    let p = (d.camera_from_model * vec4<f32>(position, 1.0)).xyz;
    // Depth 0 at the near plane, 1 at the far plane; affine in 1/z, as the CPU's 1/z buffer.
    let depth_scale = d.far / (d.far - d.near);
    var out: VsOut;
    if d.projected != 0u {
        var fb_exact = d.focal * p.xy / p.z + d.centre;
        if d.lens_model != 0u {
            fb_exact = d.focal * distort(d, p.xy / p.z) + d.centre;
        }
        let fb = floor(fb_exact * SUBPIXELS + 0.5) / SUBPIXELS;
        let ndc = vec2<f32>(fb.x / d.half_viewport.x - 1.0, 1.0 - fb.y / d.half_viewport.y);
        out.position = vec4<f32>(ndc, depth_scale * (1.0 - d.near / p.z), 1.0);
    } else {
        let fb_z = d.focal * p.xy + d.centre * p.z;
        out.position = vec4<f32>(
            fb_z.x / d.half_viewport.x - p.z,
            p.z - fb_z.y / d.half_viewport.y,
            depth_scale * (p.z - d.near),
            p.z,
        );
    }
    out.class_id = d.class_id;
    out.draw = draw;
    return out;
}

@fragment
fn fs_class(in: VsOut) -> @location(0) u32 {
    return in.class_id;
}

// Clearing one tile: a triangle covering the whole viewport, at the far plane, class none.
// (A render pass clear would clear the whole atlas; this clears only the tile.)
// The same triangle with the instance index passed on draws the mask (readback.wgsl's fs_mask).
@vertex
fn vs_clear(@builtin(vertex_index) i: u32, @builtin(instance_index) draw: u32) -> VsOut {
    let corner = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    var out: VsOut;
    out.position = vec4<f32>(corner * 2.0 - 1.0, 1.0, 1.0);
    out.class_id = 0u;
    out.draw = draw;
    return out;
}

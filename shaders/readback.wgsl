// The readback baseline, the paper's architecture: mask in white (and the visible mouth
// interior in blue), model in red at alpha 0.5 (pink over the mask), BOI in green, into a colour target that is read back whole and
// counted on the CPU (src/energy/gpu/readback.rs). Appended to raster.wgsl, whose vertex
// stages, `Draw` records and bindings it uses; tests/shaders.rs validates the two together.

@fragment
fn fs_clear_colour(in: VsOut) -> @location(0) vec4<f32> {
    return vec4<f32>(0.0, 0.0, 0.0, 0.0);
}

// The mask's label bit of the visible mouth interior (src/capture/masks.rs).
const MOUTH_BIT: u32 = 4u;

// What is under the model: the scored arch's mask pixels white, the mouth's blue, else black.
fn under_colour(d: Draw, position: vec2<f32>) -> vec3<f32> {
    let pixel = vec2<i32>(floor(position)) - d.mask_offset;
    let label = textureLoad(masks, pixel, d.layer, 0).r;
    if (label & d.arch_bit) != 0u {
        return vec3<f32>(1.0);
    }
    if (label & MOUTH_BIT) != 0u {
        return vec3<f32>(0.0, 0.0, 1.0);
    }
    return vec3<f32>(0.0);
}

// The scored arch's mask pixels in white, the mouth's in blue.
@fragment
fn fs_mask(in: VsOut) -> @location(0) vec4<f32> {
    let under = under_colour(draws[in.draw], in.position.xy);
    if all(under == vec3<f32>(0.0)) {
        discard;
    }
    return vec4<f32>(under, 1.0);
}

// Body red, BOI green, at alpha 0.5 over the mask's white or black. The mix
// is what the paper's alpha blending gives, computed here and written without blending, so
// that surfaces meeting at exactly the same depth (both pass the equal-depth test) do not
// blend twice. Class none (the other arch in per-arch mode) only hides: it was drawn in the
// depth pre-pass.
@fragment
fn fs_colour(in: VsOut) -> @location(0) vec4<f32> {
    if in.class_id == 0u {
        discard;
    }
    let under = under_colour(draws[in.draw], in.position.xy);
    let model = select(vec3<f32>(0.0, 1.0, 0.0), vec3<f32>(1.0, 0.0, 0.0), in.class_id == 1u);
    return vec4<f32>(mix(under, model, 0.5), 1.0);
}

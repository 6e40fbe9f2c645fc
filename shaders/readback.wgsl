// The readback baseline, the paper's architecture: mask in white, model in red at alpha 0.5
// (pink over the mask), BOI in green, into a colour target that is read back whole and
// counted on the CPU (src/energy/gpu/readback.rs). Appended to raster.wgsl, whose vertex
// stages, `Draw` records and bindings it uses; tests/shaders.rs validates the two together.

@fragment
fn fs_clear_colour(in: VsOut) -> @location(0) vec4<f32> {
    return vec4<f32>(0.0, 0.0, 0.0, 0.0);
}

// The scored arch's mask pixels in white.
@fragment
fn fs_mask(in: VsOut) -> @location(0) vec4<f32> {
    let d = draws[in.draw];
    let pixel = vec2<i32>(floor(in.position.xy)) - d.mask_offset;
    let label = textureLoad(masks, pixel, d.layer, 0).r;
    if (label & d.arch_bit) == 0u {
        discard;
    }
    return vec4<f32>(1.0, 1.0, 1.0, 1.0);
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
    let d = draws[in.draw];
    let pixel = vec2<i32>(floor(in.position.xy)) - d.mask_offset;
    let on_mask = (textureLoad(masks, pixel, d.layer, 0).r & d.arch_bit) != 0u;
    let under = select(vec3<f32>(0.0), vec3<f32>(1.0), on_mask);
    let model = select(vec3<f32>(0.0, 1.0, 0.0), vec3<f32>(1.0, 0.0, 0.0), in.class_id == 1u);
    return vec4<f32>(mix(under, model, 0.5), 1.0);
}

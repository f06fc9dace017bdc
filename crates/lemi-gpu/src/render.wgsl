// lemi reference renderer entry points (appended to shading.wgsl).
// Target 0: Rgba8UnormSrgb colour, alpha 1 where geometry. Target 1: R32Uint holding the bits of the
// f32 linear view depth (R32Float is not renderable on every backend, e.g. GLES without
// EXT_color_buffer_float; R32Uint is).

struct FragmentOut {
    @location(0) color: vec4<f32>,
    @location(1) depth: u32,
};

@vertex
fn vs_main(v: VertexIn) -> VertexOut {
    return transform_vertex(v);
}

@fragment
fn fs_main(in: VertexOut) -> FragmentOut {
    let albedo = surface_albedo(in);
    if (albedo.a < globals.params.x) {
        discard;
    }
    var out: FragmentOut;
    out.color = vec4<f32>(shade(albedo.rgb, in.normal), 1.0);
    out.depth = bitcast<u32>(in.view_depth);
    return out;
}

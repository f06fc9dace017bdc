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

fn geometry_output(albedo: vec4<f32>, in: VertexOut) -> FragmentOut {
    var out: FragmentOut;
    out.color = vec4<f32>(shade(albedo.rgb, in.normal), 1.0);
    out.depth = bitcast<u32>(in.view_depth);
    return out;
}

// With an alpha cutoff: fragments whose albedo alpha is below it are discarded.
@fragment
fn fs_main(in: VertexOut) -> FragmentOut {
    let albedo = surface_albedo(in);
    if (albedo.a < globals.params.x) {
        discard;
    }
    return geometry_output(albedo, in);
}

// Without one (cutoff 0: no alpha is below it): the same output without the discard, so that the
// rasterizer may test depth before shading, as any renderer draws opaque geometry.
@fragment
fn fs_main_opaque(in: VertexOut) -> FragmentOut {
    return geometry_output(surface_albedo(in), in);
}

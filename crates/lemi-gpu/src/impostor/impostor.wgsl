// lemi impostor quads (appended to shading.wgsl): the layered far field of one view cell, drawn as
// textured quads (GI 2002 sec. 3). Unlit: the macro-texture texels are final sRGB colours copied
// to the colour target unchanged: either an Rgba8Unorm macro-texture into the Rgba8Unorm view of
// the colour target (no conversion at all), or (GL, no such views) an Rgba8UnormSrgb one into the
// sRGB target, decoded and re-encoded, which round-trips exactly. Alpha test against
// globals.params.y (fs_quad; fs_quad_opaque for quads whose texels all pass it), then the same
// targets as render.wgsl: Target 0: colour, alpha 1 where drawn. Target 1: R32Uint holding the
// bits of the f32 linear view depth.
//
// The texel is fetched with textureLoad (nearest, clamped to the quad's rectangle); the sampler
// binding stays in the layout, unused (a sampler's filtering would mix micro-textures). Where a texel spans less than two
// pixels and globals.params.z is 1, the colour is the mean of an n×n grid of such fetches over the
// pixel's footprint (n = ⌈2 · texels per pixel⌉, at most 4: the footprint sampled at twice the
// texel rate; opaque texels only, averaged in linear light: globals.params.w is 1 where the texels
// hold sRGB-encoded bytes), while the alpha test still takes the one texel under the pixel's
// centre: coverage stays exact.
// Group 1 holds the atlas page of macro-textures at bindings 3 and 4 so that they never alias the material
// bindings 0..=2 the shading module declares (unused here).

struct QuadIn {
    @location(0) position: vec3<f32>,
    // macro-texture coordinates in texels
    @location(1) uv: vec2<f32>,
    // the quad's texel rectangle [x0, y0, x1, y1] in the macro-texture
    @location(2) rect: vec4<f32>,
    // the macro-texture's top-left texel in its atlas page
    @location(3) offset: vec2<u32>,
};

struct QuadOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) uv: vec2<f32>,
    @location(1) view_depth: f32,
    @location(2) @interpolate(flat) rect: vec4<f32>,
    @location(3) @interpolate(flat) offset: vec2<u32>,
};

struct QuadFragmentOut {
    @location(0) color: vec4<f32>,
    @location(1) depth: u32,
};

@group(1) @binding(3) var macro_texture: texture_2d<f32>;
@group(1) @binding(4) var macro_sampler: sampler;

@vertex
fn vs_quad(v: QuadIn) -> QuadOut {
    // Relative to the eye before any matrix product, as transform_vertex does.
    let rel = eye_relative(v.position);
    var out: QuadOut;
    out.clip = globals.clip_from_rel * vec4<f32>(rel, 1.0);
    out.uv = v.uv;
    out.rect = v.rect;
    out.offset = v.offset;
    out.view_depth = dot(globals.depth_axis.xyz, rel);
    return out;
}

// Nearest texel, clamped to the quad's own rectangle: the quad is grown a little beyond it
// (QUAD_GROWTH_TEXELS) and must never fetch a neighbour's texels or the transparent gap. The
// texel is found in the macro-texture's own coordinates, then moved to its place in the atlas
// page by an integer offset, so the fetch is exactly the macro-texture's texel.
fn texel_at(in: QuadOut, uv: vec2<f32>) -> vec4<f32> {
    let texel = clamp(floor(uv), in.rect.xy, in.rect.zw - vec2<f32>(1.0, 1.0));
    return textureLoad(macro_texture, vec2<i32>(texel) + vec2<i32>(in.offset), 0);
}

fn srgb_to_linear(c: vec3<f32>) -> vec3<f32> {
    let lo = c / 12.92;
    let hi = pow((c + vec3<f32>(0.055)) / 1.055, vec3<f32>(2.4));
    return select(hi, lo, c <= vec3<f32>(0.04045));
}

fn linear_to_srgb(c: vec3<f32>) -> vec3<f32> {
    let lo = c * 12.92;
    let hi = 1.055 * pow(c, vec3<f32>(1.0 / 2.4)) - vec3<f32>(0.055);
    return select(hi, lo, c <= vec3<f32>(0.0031308));
}

// The colour a pixel shows: its centre texel `centre` where a texel spans at least two pixels
// (or filtering is off), else the mean over the pixel's footprint (texel offsets `dx`, `dy` per
// pixel along the screen axes) of the opaque texels an n×n grid of sample points lands on.
fn quad_color(in: QuadOut, centre: vec4<f32>, dx: vec2<f32>, dy: vec2<f32>) -> vec3<f32> {
    let s = max(length(dx), length(dy));
    if (globals.params.z < 0.5 || !(s > 0.5)) {
        return centre.rgb;
    }
    let n = i32(min(ceil(2.0 * s), 4.0));
    let encoded = globals.params.w > 0.5;
    var sum = vec3<f32>(0.0);
    var count = 0.0;
    for (var j = 0; j < n; j++) {
        for (var i = 0; i < n; i++) {
            let o = (vec2<f32>(f32(i), f32(j)) + vec2<f32>(0.5)) / f32(n) - vec2<f32>(0.5);
            let t = texel_at(in, in.uv + o.x * dx + o.y * dy);
            if (t.a >= globals.params.y) {
                var c = t.rgb;
                if (encoded) {
                    c = srgb_to_linear(c);
                }
                sum += c;
                count += 1.0;
            }
        }
    }
    if (count < 0.5) {
        return centre.rgb;
    }
    var mean = sum / count;
    if (encoded) {
        mean = linear_to_srgb(mean);
    }
    return mean;
}

fn quad_output(color: vec3<f32>, in: QuadOut) -> QuadFragmentOut {
    var out: QuadFragmentOut;
    out.color = vec4<f32>(color, 1.0);
    out.depth = bitcast<u32>(in.view_depth);
    return out;
}

// Quads with texels below the alpha cutoff.
@fragment
fn fs_quad(in: QuadOut) -> QuadFragmentOut {
    // derivatives first, in uniform control flow
    let dx = dpdx(in.uv);
    let dy = dpdy(in.uv);
    let t = texel_at(in, in.uv);
    if (t.a < globals.params.y) {
        discard;
    }
    return quad_output(quad_color(in, t, dx, dy), in);
}

// Quads whose texels all pass the alpha test (decided on the CPU): the same output without the
// test, so the rasterizer can test and write depth before shading.
@fragment
fn fs_quad_opaque(in: QuadOut) -> QuadFragmentOut {
    let dx = dpdx(in.uv);
    let dy = dpdy(in.uv);
    return quad_output(quad_color(in, texel_at(in, in.uv), dx, dy), in);
}

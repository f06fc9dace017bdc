// lemi impostor quads (appended to shading.wgsl): the layered far field of one view cell, drawn as
// textured quads (GI 2002 sec. 3). Unlit: the macro-texture texels are final sRGB colours copied
// to the colour target unchanged: either an Rgba8Unorm macro-texture into the Rgba8Unorm view of
// the colour target (no conversion at all), or (GL, no such views) an Rgba8UnormSrgb one into the
// sRGB target, decoded and re-encoded, which round-trips exactly. Alpha test against
// globals.params.y (fs_quad; fs_quad_opaque for quads whose texels all pass it), then the same
// targets as render.wgsl: Target 0: colour, alpha 1 where drawn. Target 1: R32Uint holding the
// bits of the f32 linear view depth.
//
// The texel is fetched with textureLoad (nearest, clamped to the quad's rectangle). Where a texel
// spans less than two pixels and FOOTPRINT is set, the colour is filtered instead (quad_color)
// from bilinear fetches that never leave the quad's rectangle, while the alpha test still takes the
// one texel under the pixel's centre: coverage stays exact.
// Outline fringe (lemi_core::compress::outline_fringe): texels with alpha in
// [globals.params.z, globals.params.y) fail the first test; fs_quad_fringe draws them in a pass of
// their own, after everything else, only on pixels where something was drawn before (the depth
// buffer as the earlier passes left it, copied to group 2: reverse-Z 0 where nothing was).
// Group 1 holds the atlas page of macro-textures at bindings 3..=6 so that they never alias the
// material bindings 0..=2 the shading module declares (unused here): the page as stored (3), a
// bilinear sampler (4), the page decoded to linear light (5) and the page's parameters (6).

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

struct PageParams {
    // x: 1 where transparent texels are transparent black, so a filtered fetch's colour over its
    // alpha is the mean of the opaque texels it mixed (RGBA8 pages, BC1); 0 where they carry the
    // colour of their neighbours (BC7) and the fetch's colour is taken as it is.
    flags: vec4<f32>,
};

// Whether minified quads are filtered (TexelFilter::Footprint), fixed per pipeline.
override FOOTPRINT: bool = true;

@group(1) @binding(3) var macro_texture: texture_2d<f32>;
@group(1) @binding(4) var macro_sampler: sampler;
@group(1) @binding(5) var macro_linear: texture_2d<f32>;
@group(1) @binding(6) var<uniform> page: PageParams;
@group(2) @binding(0) var drawn_depth: texture_depth_2d;

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

fn linear_to_srgb(c: vec3<f32>) -> vec3<f32> {
    let lo = c * 12.92;
    let hi = 1.055 * pow(c, vec3<f32>(1.0 / 2.4)) - vec3<f32>(0.055);
    return select(hi, lo, c <= vec3<f32>(0.0031308));
}

// One bilinear fetch in linear light at texel-space point p of the quad's macro-texture, moved to
// the nearest texel corner when `snap` (then it is the exact mean of the 2×2 texels around it) and
// clamped to half a texel inside the quad's rectangle, so it never mixes in a texel of another
// micro-texture or of the transparent gap (a one-texel-wide rectangle gives its texels exactly).
fn filtered_tap(in: QuadOut, p: vec2<f32>, snap: bool, size: vec2<f32>) -> vec4<f32> {
    var q = p;
    if (snap) {
        q = round(p);
    }
    q = clamp(q, in.rect.xy + vec2<f32>(0.5), in.rect.zw - vec2<f32>(0.5));
    return textureSampleLevel(macro_linear, macro_sampler, (q + vec2<f32>(in.offset)) / size, 0.0);
}

// The colour a pixel shows: its centre texel `centre` where a texel spans at least two pixels
// (or filtering is off), else a filter of its footprint (texel offsets `dx`, `dy` per pixel along
// the screen axes, s texels across at most), averaged in linear light over opaque texels only:
// - s ≤ 1: one bilinear fetch at the pixel's centre (the tent filter of texture hardware);
// - 1 < s ≤ 2: one fetch at the texel corner nearest the centre, the mean of the 2×2 texels
//   around it;
// - s > 2: four such fetches at the centres of the footprint's quarters, the mean of up to 4×4
//   texels (exact up to s = 4; beyond, the footprint is sampled, not covered).
fn quad_color(in: QuadOut, centre: vec4<f32>, dx: vec2<f32>, dy: vec2<f32>) -> vec3<f32> {
    let s = max(length(dx), length(dy));
    if (!FOOTPRINT || !(s > 0.5)) {
        return centre.rgb;
    }
    // The fetches run in a loop of as many turns as the pixel needs, not in a branch: a software
    // rasterizer runs both sides of a branch for a group of pixels, and a loop for as many turns
    // as its neediest pixel takes (on llvmpipe at least one), so a group whose texels span at
    // most two pixels pays for one fetch, not five.
    let taps = select(1, 4, s > 2.0);
    let size = vec2<f32>(textureDimensions(macro_linear));
    var sum = vec4<f32>(0.0);
    for (var k = 0; k < taps; k++) {
        var p = in.uv;
        if (taps == 4) {
            // the centres of the footprint's quarters: ±¼ of it along each screen axis
            let o = vec2<f32>(f32(k & 1), f32(k >> 1u)) - vec2<f32>(0.5);
            p += 0.5 * (o.x * dx + o.y * dy);
        }
        sum += filtered_tap(in, p, s > 1.0, size);
    }
    sum /= f32(taps);
    var mean = sum.rgb;
    if (page.flags.x > 0.5) {
        if (!(sum.a > 1.0 / 256.0)) {
            return centre.rgb;
        }
        mean = sum.rgb / sum.a;
    }
    if (globals.params.w > 0.5) {
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

// Whether the earlier passes drew pixel p; beyond the frame, where that is not known, true.
fn drawn_at(p: vec2<i32>) -> bool {
    let size = vec2<i32>(textureDimensions(drawn_depth));
    if (any(p < vec2<i32>(0)) || any(p >= size)) {
        return true;
    }
    return textureLoad(drawn_depth, p, 0) > 0.0;
}

// The outline fringe texels of a quad (alpha in [globals.params.z, globals.params.y)), each drawn
// only where it can close a gap: over a pixel that already shows something (a farther surface,
// beside an outline that parallax moved), or in a gap of one or two pixels between pixels
// that do (two outlines whose fringes face each other: the geometry's slit between them may be
// narrower than a pixel, where the reference shows no background). Over open background it would
// only fatten the silhouette.
@fragment
fn fs_quad_fringe(in: QuadOut) -> QuadFragmentOut {
    let dx = dpdx(in.uv);
    let dy = dpdy(in.uv);
    let t = texel_at(in, in.uv);
    if (t.a < globals.params.z || t.a >= globals.params.y) {
        discard;
    }
    return fringe_output(in, t, dx, dy);
}

// The texels of a fringe quad (lemi_core::bundle::Quad::fringe: a format without the fringe's
// alpha level keeps its fringe texels in quads of their own, fully opaque), drawn as
// fs_quad_fringe draws the fringe texels of other quads.
@fragment
fn fs_quad_fringe_quads(in: QuadOut) -> QuadFragmentOut {
    let dx = dpdx(in.uv);
    let dy = dpdy(in.uv);
    let t = texel_at(in, in.uv);
    if (t.a < globals.params.z) {
        discard;
    }
    return fringe_output(in, t, dx, dy);
}

// A fringe texel t: shown where it can close a gap (see fs_quad_fringe), discarded elsewhere.
fn fringe_output(in: QuadOut, t: vec4<f32>, dx: vec2<f32>, dy: vec2<f32>) -> QuadFragmentOut {
    let p = vec2<i32>(in.clip.xy);
    var show = textureLoad(drawn_depth, p, 0) > 0.0;
    if (!show) {
        // drawn pixels on both sides of a gap of at most two pixels, along the row or the column
        let l1 = drawn_at(p + vec2<i32>(-1, 0));
        let r1 = drawn_at(p + vec2<i32>(1, 0));
        let u1 = drawn_at(p + vec2<i32>(0, -1));
        let d1 = drawn_at(p + vec2<i32>(0, 1));
        let row = (l1 && (r1 || drawn_at(p + vec2<i32>(2, 0)))) || (r1 && drawn_at(p + vec2<i32>(-2, 0)));
        let column = (u1 && (d1 || drawn_at(p + vec2<i32>(0, 2)))) || (d1 && drawn_at(p + vec2<i32>(0, -2)));
        show = row || column;
    }
    if (!show) {
        discard;
    }
    return quad_output(quad_color(in, t, dx, dy), in);
}

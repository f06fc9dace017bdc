// lemi layer recorder entry points (appended to shading.wgsl): crack-free layer recording
// (TR-186-2-02-04 sec. 2.2) with overestimated conservative rasterization by triangle dilation in
// the vertex shader (Hasselgren, Akenine-Möller, Ohlsson, "Conservative Rasterization", GPU Gems 2,
// ch. 42). Every vertex carries all three corners of its triangle in canonical order (so the three
// vertices compute the same triangle-level decisions bit for bit) and its own corner index.
// Attributes: each moved corner gets its barycentric coordinates with respect to the original
// triangle (perspective-correct, on the triangle's plane); the fragment shader clamps the
// interpolated barycentrics to the triangle and interpolates the corners' attributes (flat inputs)
// with them, so interior texels get exactly the original interpolation and the overshoot gets the
// nearest values on the triangle (no extrapolated colours or UVs).
// Targets as in render.wgsl: 0 = Rgba8UnormSrgb colour, 1 = R32Uint bits of the f32 linear depth.
// Alpha is 1, or ½ where the texel's point lies behind the side plane at depth globals.depth_axis.w
// (the layer's plane, for the bake's outline copies; 0: no side plane). With globals.eye_lo.w = 1
// (overshoot marked, for the bake's outline fringe) a texel whose centre lies outside its
// triangle has alpha lowered by a further ¼, and its depth is pushed back far enough (×2^-10 in
// reverse Z) that a triangle of the slab containing the centre wins the texel at any depth: a
// texel then reads as overshoot only when no triangle of the slab covers its centre.
// Uniforms: globals.params = (alpha cutoff, Res, near plane, coverage mode). Coverage mode 0 is the
// conservative coverage above; 1 is ordinary rasterization (a texel is covered when its centre is
// inside the projected triangle, as in render.wgsl), for strategies that record without it
// (Schaufler's layered impostors): the vertex shader emits the original corners and the fragment
// shader skips the texel/triangle overlap test and the overshoot depth push-back. The conservative
// path computes exactly what it did before the mode existed (the mode only selects at the end).
// Mode 2 covers a texel when its centre is inside the triangle (as ordinary rasterization) or its
// square touches one of the triangle's clipping edges (edges on a slab border, flagged per vertex
// from bit 2 of `corner`): silhouettes land where ordinary rasterization puts them while every
// texel a cut passes through is covered, so cuts stay crack-free. A triangle without clipping
// edges is rasterized as it is; one with clipping edges is dilated as in mode 0 and tested here.

struct RecIn {
    @location(0) p0: vec3<f32>,
    @location(1) p1: vec3<f32>,
    @location(2) p2: vec3<f32>,
    @location(3) corner: u32,
    @location(4) n0: vec3<f32>,
    @location(5) n1: vec3<f32>,
    @location(6) n2: vec3<f32>,
    @location(7) uv01: vec4<f32>,
    @location(8) uv2: vec2<f32>,
    @location(9) c0: vec4<f32>,
    @location(10) c1: vec4<f32>,
    @location(11) c2: vec4<f32>,
};

struct RecOut {
    @builtin(position) clip: vec4<f32>,
    // Barycentric coordinates with respect to the original triangle.
    @location(0) bary: vec3<f32>,
    @location(1) view_depth: f32,
    // The projected triangle in framebuffer pixels (p0, p1) and (p2, its depth range).
    @location(2) @interpolate(flat) tri01: vec4<f32>,
    @location(3) @interpolate(flat) tri2: vec4<f32>,
    @location(4) @interpolate(flat) n0: vec3<f32>,
    @location(5) @interpolate(flat) n1: vec3<f32>,
    @location(6) @interpolate(flat) n2: vec3<f32>,
    @location(7) @interpolate(flat) uv01: vec4<f32>,
    @location(8) @interpolate(flat) uv2: vec2<f32>,
    @location(9) @interpolate(flat) c0: vec4<f32>,
    @location(10) @interpolate(flat) c1: vec4<f32>,
    @location(11) @interpolate(flat) c2: vec4<f32>,
    // Mode 2: bit k set when edge k → k+1 is a clipping edge.
    @location(12) @interpolate(flat) clip_edges: u32,
};

struct FragmentOut {
    @location(0) color: vec4<f32>,
    @location(1) depth: u32,
    @builtin(frag_depth) z: f32,
};

// Half a texel in framebuffer pixels, grown by 1/128 px so that squares merely touching the
// triangle count as covered despite f32 rounding: the clip-border texels are found in f64
// (`lemi_core::clip_border`), and a cut that grazes a texel by 0.0006 px (found on a city cell)
// must still be covered in both layers, or gap filling has to copy it one layer back.
const HALF: f32 = 0.5078125;
// Slack of the clip-edge mode's centre test (px): more than the rasterizer's vertex snapping.
const TIE: f32 = 1.0 / 64.0;

fn to_pixel(c: vec4<f32>) -> vec2<f32> {
    let res = globals.params.y;
    return vec2<f32>((c.x / c.w + 1.0) * 0.5 * res, (1.0 - c.y / c.w) * 0.5 * res);
}

fn to_clip_xy(p: vec2<f32>, w: f32) -> vec4<f32> {
    let res = globals.params.y;
    let ndc = vec2<f32>(2.0 * p.x / res - 1.0, 1.0 - 2.0 * p.y / res);
    // Reverse-Z infinite projection: clip z is the near distance for every point, w the depth.
    return vec4<f32>(ndc * w, globals.params.z, w);
}

// The line through a and b as (n, c) with n·p + c = 0, n pointing to the left of a → b.
fn edge_line(a: vec2<f32>, b: vec2<f32>) -> vec3<f32> {
    let n = vec2<f32>(a.y - b.y, b.x - a.x);
    return vec3<f32>(n, -dot(n, a));
}

@vertex
fn vs_main(v: RecIn) -> RecOut {
    let rel = array<vec3<f32>, 3>(v.p0, v.p1, v.p2);
    let k = (v.corner & 3u) % 3u;
    // Mode 2: which edges are clipping edges (a triangle without any is not dilated, below).
    let clip_edges = (v.corner >> 2u) & 7u;
    var clip: array<vec4<f32>, 3>;
    var px: array<vec2<f32>, 3>;
    for (var i = 0u; i < 3u; i++) {
        clip[i] = globals.clip_from_rel * vec4<f32>(rel[i], 1.0);
        px[i] = to_pixel(clip[i]);
    }
    let lo = min(min(px[0], px[1]), px[2]) - vec2<f32>(HALF);
    let hi = max(max(px[0], px[1]), px[2]) + vec2<f32>(HALF);
    let w_min = min(min(clip[0].w, clip[1].w), clip[2].w);
    let w_max = max(max(clip[0].w, clip[1].w), clip[2].w);

    // Signed doubled area in pixels²; positive orientation after the flip below.
    let e1 = px[1] - px[0];
    let e2 = px[2] - px[0];
    let area2 = e1.x * e2.y - e1.y * e2.x;
    let orient = select(-1.0, 1.0, area2 >= 0.0);

    // Dilation: every edge line moved outward by half a texel diagonal in the L1 sense
    // (c' = c + h (|n.x| + |n.y|), GPU Gems 2 ch. 42, "overestimated" variant), and each corner
    // replaced by the intersection of its two adjacent moved edges.
    var moved: array<vec2<f32>, 3>;
    var ok = abs(area2) >= 1.0;
    for (var i = 0u; i < 3u; i++) {
        let a = (i + 2u) % 3u; // edge a → i
        let b = (i + 1u) % 3u; // edge i → b
        var l0 = edge_line(px[a], px[i]) * orient;
        var l1 = edge_line(px[i], px[b]) * orient;
        l0.z += HALF * (abs(l0.x) + abs(l0.y));
        l1.z += HALF * (abs(l1.x) + abs(l1.y));
        let h = cross(l0, l1);
        if (abs(h.z) < 1e-12) {
            ok = false;
        }
        moved[i] = h.xy / h.z;
    }
    let md1 = moved[1] - moved[0];
    let md2 = moved[2] - moved[0];
    let moved_area2 = abs(md1.x * md2.y - md1.y * md2.x);
    let size = hi - lo;
    // A triangle around the grown bounding box: (lo), (lo + 2 size.x, lo.y), (lo.x, lo.y + 2 size.y).
    let box_area2 = 4.0 * size.x * size.y;
    let finite = all(abs(moved[0]) < vec2<f32>(1e30)) && all(abs(moved[1]) < vec2<f32>(1e30))
        && all(abs(moved[2]) < vec2<f32>(1e30));
    let use_dilated = ok && finite && moved_area2 <= box_area2;

    var p: vec2<f32>;
    if (use_dilated) {
        p = moved[k];
    } else {
        // Degenerate in projection (edge-on, point-like) or a sliver whose dilation overshoots:
        // a triangle covering the grown bounding box; the fragment test keeps the right texels.
        p = lo;
        if (k == 1u) {
            p.x = lo.x + 2.0 * size.x;
        } else if (k == 2u) {
            p.y = lo.y + 2.0 * size.y;
        }
    }

    // Depth of the new corner: the ray through p meets the triangle's plane, in clip (x, y, w)
    // coordinates (linear in view space), so that depth interpolates exactly on the plane; the
    // fragment shader clamps it to the triangle's depth range. An edge-on triangle keeps the
    // corner's own depth.
    let q0 = clip[0].xyw;
    let nrm = cross(clip[1].xyw - q0, clip[2].xyw - q0);
    let res = globals.params.y;
    let ray = vec3<f32>(2.0 * p.x / res - 1.0, 1.0 - 2.0 * p.y / res, 1.0);
    let denom = dot(nrm, ray);
    var w = clip[k].w;
    var bary = vec3<f32>(0.0);
    bary[k] = 1.0;
    let t = dot(nrm, q0) / denom;
    // Plausible range: half the nearest to twice the farthest depth, never in front of the near
    // plane (else the rasterizer would clip the dilated triangle); anything else (an edge-on
    // triangle's plane contains the eye) keeps the corner's own depth.
    let w_lo = max(0.5 * w_min, min(w_min, globals.params.z));
    if (abs(denom) > 1e-30 && t >= w_lo && t <= 2.0 * w_max) {
        w = t;
        // Barycentrics of q = t · ray in the basis of the corners' clip (x, y, w) (Cramer's rule).
        let q = ray * t;
        let det = dot(q0, cross(clip[1].xyw, clip[2].xyw));
        if (abs(det) > 1e-30) {
            let b = vec3<f32>(
                dot(q, cross(clip[1].xyw, clip[2].xyw)),
                dot(q, cross(clip[2].xyw, q0)),
                dot(q, cross(q0, clip[1].xyw)),
            ) / det;
            if (all(abs(b) < vec3<f32>(1e6))) {
                bary = b;
            }
        }
    }

    var out: RecOut;
    out.clip = to_clip_xy(p, w);
    out.bary = bary;
    out.n0 = v.n0;
    out.n1 = v.n1;
    out.n2 = v.n2;
    out.uv01 = v.uv01;
    out.uv2 = v.uv2;
    out.c0 = v.c0;
    out.c1 = v.c1;
    out.c2 = v.c2;
    out.view_depth = w;
    out.tri01 = vec4<f32>(px[0], px[1]);
    out.tri2 = vec4<f32>(px[2], w_min, w_max);
    out.clip_edges = clip_edges;
    // Mode 2, a triangle without clipping edges: the original corners (as in mode 1), so a
    // triangle sharing an edge rasterizes the same line bit for bit and the rasterizer's tie
    // rule keeps the pair watertight.
    let unmoved = globals.params.w > 1.5 && clip_edges == 0u;
    if ((globals.params.w > 0.5 && globals.params.w < 1.5) || unmoved) {
        // Centre-sampled: the original corner, its own barycentrics and depth.
        var unit = vec3<f32>(0.0);
        unit[k] = 1.0;
        out.clip = clip[k];
        out.bary = unit;
        out.view_depth = clip[k].w;
    }
    return out;
}

// True when the projection of the triangle on the line direction n and that of the texel square
// centred at c (half size `half`: HALF, or 0 for the texel centre alone) are disjoint (a
// separating axis).
fn separated(n: vec2<f32>, c: vec2<f32>, a: vec2<f32>, b: vec2<f32>, d: vec2<f32>, half: f32) -> bool {
    let pa = dot(n, a);
    let pb = dot(n, b);
    let pd = dot(n, d);
    let r = half * (abs(n.x) + abs(n.y));
    let pc = dot(n, c);
    return pc + r < min(min(pa, pb), pd) || pc - r > max(max(pa, pb), pd);
}

// True when the texel square centred at c (half size HALF) touches the segment p–q.
fn touches_segment(c: vec2<f32>, p: vec2<f32>, q: vec2<f32>) -> bool {
    let e = q - p;
    return !(separated(vec2<f32>(1.0, 0.0), c, p, q, q, HALF)
        || separated(vec2<f32>(0.0, 1.0), c, p, q, q, HALF)
        || separated(vec2<f32>(-e.y, e.x), c, p, q, q, HALF));
}

@fragment
fn fs_main(in: RecOut) -> FragmentOut {
    // Nearest-ish point of the triangle: barycentrics clamped to the triangle.
    var bc = max(in.bary, vec3<f32>(0.0));
    let sum = bc.x + bc.y + bc.z;
    bc = select(vec3<f32>(1.0 / 3.0), bc / sum, sum > 1e-20);
    var s: VertexOut;
    s.clip = in.clip;
    s.normal = in.n0 * bc.x + in.n1 * bc.y + in.n2 * bc.z;
    s.uv = in.uv01.xy * bc.x + in.uv01.zw * bc.y + in.uv2 * bc.z;
    s.color = in.c0 * bc.x + in.c1 * bc.y + in.c2 * bc.z;
    s.view_depth = in.view_depth;
    // Sampled before any discard (derivatives need uniform control flow).
    let albedo = surface_albedo(s);
    // Exact texel-square / triangle overlap by separating axes (the two box axes and the three edge
    // normals): removes the dilation's overshoot at acute corners and around degenerate triangles.
    // (Not in the centre-sampled mode: the rasterizer's own coverage is the answer there, nor in
    // mode 2 for a triangle without clipping edges, which is rasterized undilated.)
    let mode2 = globals.params.w > 1.5;
    let conservative = globals.params.w <= 0.5 || (mode2 && in.clip_edges != 0u);
    let c = in.clip.xy;
    let a = in.tri01.xy;
    let b = in.tri01.zw;
    let d = in.tri2.xy;
    let eab = b - a;
    let ebd = d - b;
    let eda = a - d;
    if (mode2 && conservative) {
        // Centre inside the triangle, or the square touching a clipping edge (separating axes
        // of a segment). Inside is inclusive by TIE px, so that a neighbour across a shared edge
        // rasterized by the hardware (vertices snapped to its sub-pixel grid) never leaves a
        // centre on the edge to neither triangle.
        let inside = !(separated(vec2<f32>(-eab.y, eab.x), c, a, b, d, TIE)
            || separated(vec2<f32>(-ebd.y, ebd.x), c, a, b, d, TIE)
            || separated(vec2<f32>(-eda.y, eda.x), c, a, b, d, TIE));
        let touch = ((in.clip_edges & 1u) != 0u && touches_segment(c, a, b))
            || ((in.clip_edges & 2u) != 0u && touches_segment(c, b, d))
            || ((in.clip_edges & 4u) != 0u && touches_segment(c, d, a));
        if (!(inside || touch)) {
            discard;
        }
    } else if (conservative) {
        if (separated(vec2<f32>(1.0, 0.0), c, a, b, d, HALF)
            || separated(vec2<f32>(0.0, 1.0), c, a, b, d, HALF)
            || separated(vec2<f32>(-eab.y, eab.x), c, a, b, d, HALF)
            || separated(vec2<f32>(-ebd.y, ebd.x), c, a, b, d, HALF)
            || separated(vec2<f32>(-eda.y, eda.x), c, a, b, d, HALF)) {
            discard;
        }
    }
    if (albedo.a < globals.params.x) {
        discard;
    }
    var out: FragmentOut;
    let depth = clamp(in.view_depth, in.tri2.z, in.tri2.w);
    // The side plane (globals.depth_axis.w, 0 when none): alpha ½ marks a point behind it.
    let plane = globals.depth_axis.w;
    let behind = plane > 0.0 && depth > plane;
    // (Centre-sampled texels are inside by definition.)
    let inside = min(min(in.bary.x, in.bary.y), in.bary.z) >= 0.0 || !conservative;
    let mark = globals.eye_lo.w > 0.5;
    let over = select(0.0, 0.25, mark && !inside);
    out.color = vec4<f32>(shade(albedo.rgb, s.normal), select(1.0, 0.5, behind) - over);
    out.depth = bitcast<u32>(depth);
    // A texel whose centre lies outside the triangle (conservative overshoot) loses the depth test
    // against a triangle that contains the centre at the same depth (the neighbour across a shared
    // edge), so shared edges keep the colour the reference renderer gives them: its reverse-Z depth
    // is pushed back by a relative 2^-16.
    // Marked overshoot (above) is pushed back further: any triangle containing the centre wins.
    let push = select(1.0 - 1.0 / 65536.0, 1.0 / 1024.0, mark);
    out.z = select(in.clip.z * push, in.clip.z, inside);
    return out;
}

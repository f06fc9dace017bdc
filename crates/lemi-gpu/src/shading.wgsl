// lemi shading: the one shading model every lemi pipeline shares (reference renderer, layer
// recorder, impostor renderer), so that impostors and the ground truth they are compared with agree.
//
// colour = base_color_factor × texture (sRGB-decoded by the texture format) × vertex colour
//          × (ambient + sun · |n · L|)
// Lambertian diffuse (Lambert's cosine law, Photometria 1760), two-sided (|n·L|) because scenes
// are polygon soups without consistent winding.
//
// Group 0: per-pass globals (view relative to the eye, lighting). Group 1: per-material.
// Vertex layout: lemi_core::Vertex (position f32x3, normal f32x3, uv f32x2, colour unorm8x4).

struct Globals {
    // Projection × view rotation (no translation): clip = clip_from_rel · (p − eye, 1).
    clip_from_rel: mat4x4<f32>,
    // The eye split as hi + lo for precision far from the origin.
    eye_hi: vec4<f32>,
    eye_lo: vec4<f32>,
    // View depth (distance along the view axis) = dot(depth_axis, p − eye).
    depth_axis: vec4<f32>,
    // Unit vector towards the directional light (world space).
    light_dir: vec4<f32>,
    // Linear RGB of the directional light and of the ambient term.
    light_color: vec4<f32>,
    ambient: vec4<f32>,
    // x: alpha cutoff (fragments with albedo alpha below it are discarded; 0 keeps all).
    params: vec4<f32>,
};

struct MaterialUniform {
    // Linear RGBA base colour factor.
    base_color: vec4<f32>,
};

@group(0) @binding(0) var<uniform> globals: Globals;
@group(1) @binding(0) var<uniform> material: MaterialUniform;
@group(1) @binding(1) var base_texture: texture_2d<f32>;
@group(1) @binding(2) var base_sampler: sampler;

struct VertexIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) uv: vec2<f32>,
    @location(3) color: vec4<f32>,
};

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    @location(1) uv: vec2<f32>,
    @location(2) color: vec4<f32>,
    @location(3) view_depth: f32,
};

// p − eye, computed before any matrix product so large coordinates keep their precision.
fn eye_relative(p: vec3<f32>) -> vec3<f32> {
    return (p - globals.eye_hi.xyz) - globals.eye_lo.xyz;
}

fn transform_vertex(v: VertexIn) -> VertexOut {
    let rel = eye_relative(v.position);
    var out: VertexOut;
    out.clip = globals.clip_from_rel * vec4<f32>(rel, 1.0);
    out.normal = v.normal;
    out.uv = v.uv;
    out.color = v.color;
    out.view_depth = dot(globals.depth_axis.xyz, rel);
    return out;
}

// Whether the pipeline draws textured materials, fixed per pipeline (a pipeline constant). An
// untextured material has a bound 1×1 white texture, whose sample is exactly 1; its pipeline
// (TEXTURED = false) takes that 1 as a constant, so the compiler drops the fetch (a trilinear,
// sRGB-decoding sample that costs about as much as the rest of the shading on a software
// rasterizer) and the albedo is bit for bit what the sample would give.
override TEXTURED: bool = true;

// Linear RGBA albedo of a fragment: base colour factor × texture × vertex colour. Untextured
// materials sample a bound 1×1 white texture where TEXTURED is set. The fetch stays outside any
// branch (a `select` on a pipeline constant, which the compiler folds): a fetch inside one
// (skipping the white texture) made Mesa's lavapipe 22.3 keep memory for every fragment group
// it shaded, for the life of the device (a 6-cell bake grew to 11 GB, and recorded at half speed);
// tests/recorder_memory.rs fails if such a fetch comes back.
fn surface_albedo(in: VertexOut) -> vec4<f32> {
    let t = select(vec4<f32>(1.0), textureSample(base_texture, base_sampler, in.uv), TEXTURED);
    return material.base_color * t * in.color;
}

// Two-sided Lambert: albedo × (ambient + sun · |n·L|). A degenerate interpolated normal gets
// ambient only.
fn shade(albedo: vec3<f32>, normal: vec3<f32>) -> vec3<f32> {
    let len2 = dot(normal, normal);
    var ndl = 0.0;
    if (len2 > 1e-20) {
        ndl = abs(dot(normal * inverseSqrt(len2), globals.light_dir.xyz));
    }
    return albedo * (globals.ambient.rgb + globals.light_color.rgb * ndl);
}

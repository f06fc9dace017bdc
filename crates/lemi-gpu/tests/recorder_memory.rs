//! The layer recorder's memory stays bounded however many layers it records. A test binary of its
//! own: it reads the process's resident set, which tests running in other threads would move.
//!
//! Why it exists: a texture fetch inside a branch of the shading module (sampling a material's
//! texture only when it has one) made Mesa's lavapipe (22.3, Vulkan) keep memory for every
//! fragment group it shaded, for the life of the device: a bake of 6 `builtin:city:1M` cells grew
//! to 11 GB resident, `lemi compare` ran out of 24 GB, and recording took twice as long. The GL
//! backend on the same rasterizer did not grow. On an adapter without the fault this test passes
//! whatever the shader does; on lavapipe it fails if such a fetch comes back.

use glam::DVec3;
use lemi_core::Face;
use lemi_gpu::{LayerRecorder, Lighting};
use lemi_testkit::{gpu, one_run, skip, wavy_surface, white_materials};

/// The resident set of this process in bytes (Linux), from `/proc/self/status`.
fn resident_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

#[test]
fn recording_many_layers_keeps_memory_bounded() {
    let Some(gpu) = gpu() else { return };
    if resident_bytes().is_none() {
        skip("no /proc/self/status to read the resident set from (not Linux)");
        return;
    }
    let res = 512;
    let rec = LayerRecorder::new(&gpu, res).expect("recorder");
    let materials = white_materials(&gpu);
    let lighting = Lighting::default();
    let center = DVec3::new(10.0, 2.0, -30.0);
    // 2 × 120² triangles over the middle 0.7 × 0.7 of the face: 49 % of its texels shaded
    let surface = wavy_surface(Face::PosZ, 120);
    let runs = one_run(&surface);
    let record = || {
        rec.record(
            &materials,
            center,
            Face::PosZ,
            &surface,
            &runs,
            0.1,
            &lighting,
        )
        .expect("record")
    };
    // warm-up: pipelines compiled, targets and readback buffers allocated, allocator settled
    for _ in 0..5 {
        record();
    }
    let before = resident_bytes().expect("resident set");
    let layers = 60;
    let mut covered = 0usize;
    for _ in 0..layers {
        let frame = record();
        covered = frame.rgba.chunks_exact(4).filter(|p| p[3] > 0).count();
    }
    let after = resident_bytes().expect("resident set");
    assert!(
        covered > (res * res / 3) as usize,
        "the surface covers {covered} texels: too few for the test to mean anything"
    );
    let grown = after.saturating_sub(before);
    // With the fault this grew by 106 MB (1.8 MB a layer of this size); a recorder that frees
    // what it allocates stays within the allocator's slack.
    assert!(
        grown < 32 << 20,
        "recording {layers} layers grew the resident set by {:.1} MB ({:.2} MB a layer)",
        grown as f64 / (1 << 20) as f64,
        grown as f64 / (1 << 20) as f64 / layers as f64
    );
}

//! Throughput of the layer recorder at 512² (a measurement, not a test): a wavy surface of 0, 3 200
//! and 12 800 triangles recorded ten times each, with readback.
//! `cargo run --release -p lemi-gpu --example recorder_throughput`.

use glam::DVec3;
use lemi_core::Face;
use lemi_gpu::{LayerRecorder, Lighting};
use lemi_testkit::{one_run, wavy_surface, white_materials};

fn main() {
    let Some(gpu) = lemi_testkit::gpu() else {
        return;
    };
    let rec = match LayerRecorder::new(&gpu, 512) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("error: creating the recorder: {e}");
            std::process::exit(1);
        }
    };
    let mats = white_materials(&gpu);
    let l = Lighting::default();
    for cells in [0, 40, 80] {
        let surface = wavy_surface(Face::PosZ, cells); // 2 cells² triangles
        let runs = one_run(&surface);
        let n = 10;
        let start = std::time::Instant::now();
        for _ in 0..n {
            if let Err(e) = rec.record(&mats, DVec3::ZERO, Face::PosZ, &surface, &runs, 0.1, &l) {
                eprintln!("error: recording: {e}");
                std::process::exit(1);
            }
        }
        let secs = start.elapsed().as_secs_f64() / n as f64;
        let tris = surface.len() / 3;
        println!(
            "{}: {tris} triangles in {:.2} ms per 512² layer (with readback) = {:.0} triangles/s",
            gpu.describe(),
            secs * 1e3,
            tris as f64 / secs
        );
    }
}

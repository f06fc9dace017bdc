//! The compression pipeline (GI 2002 sec. 5) on a full-size synthetic cell, as in GI 2002 sec. 6
//! (Table 2): 4 faces × 64 layers × 512², each stage timed alone and then the whole
//! `compress_cell`, with its statistics and the PNG bytes (a measurement, not a test):
//! `cargo run --release -p lemi-core --example compress_synthetic_cell`.

use std::time::Instant;

use image::ImageEncoder;
use lemi_core::compress::{
    compress_cell, extract_micro_textures, fill_gaps, pack_micro_textures, remove_hidden_texels,
    CompressOptions,
};

#[path = "../tests/common/synthetic.rs"]
mod synthetic;
use synthetic::synthetic_cell;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    for threshold in [0.4, 0.6, 0.8] {
        let mut faces = synthetic_cell(512, 64, 4, 42);
        let mut opts = CompressOptions::default();
        opts.micro.threshold = threshold;
        // each stage alone first, for its time
        let mut copy = faces.clone();
        let t = Instant::now();
        for f in &mut copy {
            fill_gaps(&mut f.layers, opts.gap_sources)?;
        }
        let t_gap = t.elapsed().as_secs_f64();
        let t = Instant::now();
        for f in &mut copy {
            remove_hidden_texels(&mut f.layers, &opts.hidden)?;
        }
        let t_hidden = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let mut micros = Vec::new();
        for f in &copy {
            for (k, l) in f.layers.iter().enumerate() {
                micros.extend(
                    extract_micro_textures(l, f.face, k as u32, f.distances[k], &opts.micro)?.0,
                );
            }
        }
        let t_micro = t.elapsed().as_secs_f64();
        let t = Instant::now();
        pack_micro_textures(&micros, &opts.packing)?;
        let t_pack = t.elapsed().as_secs_f64();
        println!(
            "threshold {threshold}: stages one after the other: gap fill {t_gap:.3} s, hidden {t_hidden:.3} s, micro {t_micro:.3} s, packing {t_pack:.3} s"
        );
        let t = Instant::now();
        let cell = compress_cell(&mut faces, &opts)?;
        let dt = t.elapsed();
        let s = &cell.stats;
        println!(
            "  compress_cell: {:.2} s on {} threads",
            dt.as_secs_f64(),
            rayon::current_num_threads()
        );
        println!(
            "  layers: {} bytes ({:.1} MB)",
            s.layer_bytes,
            s.layer_bytes as f64 / 1e6
        );
        println!("  gap fill: {:?}", s.gap_fill);
        println!(
            "  hidden: opaque {} -> {} (removed {}, {:.1}%)",
            s.hidden.opaque_before,
            s.hidden.opaque_after,
            s.hidden.removed,
            100.0 * s.hidden.removed as f64 / s.hidden.opaque_before as f64
        );
        println!(
            "  micro: {} micro-textures, {} texels, fill ratio {:.3}",
            s.micro.micro_textures, s.micro.texels, s.micro.fill_ratio
        );
        println!(
            "  packing: {} macro-textures, {} bytes ({:.2} MB), efficiency {:.3}",
            s.packing.macro_textures,
            s.packing.macro_bytes,
            s.packing.macro_bytes as f64 / 1e6,
            s.packing.efficiency
        );
        let t = Instant::now();
        let png: usize = cell
            .macro_textures
            .iter()
            .map(|m| {
                let mut bytes = Vec::new();
                image::codecs::png::PngEncoder::new(&mut bytes)
                    .write_image(&m.rgba, m.width, m.height, image::ExtendedColorType::Rgba8)
                    .map(|_| bytes.len())
                    .unwrap_or(0)
            })
            .sum();
        println!(
            "  PNG (image crate defaults): {png} bytes ({:.2} MB) in {:.2} s",
            png as f64 / 1e6,
            t.elapsed().as_secs_f64()
        );
    }
    Ok(())
}

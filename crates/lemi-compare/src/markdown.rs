//! `COMPARISON.md`: the comparison's table, the notes and the plot.

use std::fmt::Write as _;

use lemi_strategy::StrategyKind;

use crate::{encode_seconds_per_cell, BakeRow, EvalRow, FormatRow, GeometryTimes, Row};
use lemi_core::compress::TextureFormat;
use lemi_eval::AgainstResult;

fn fmt_ms(x: Option<f64>) -> String {
    x.map_or("–".into(), |v| format!("{v:.1}"))
}

fn fmt_bytes(x: Option<f64>) -> String {
    match x {
        None => "–".into(),
        Some(b) if b >= 1e6 => format!("{:.2} MB", b / 1e6),
        Some(b) if b >= 1e3 => format!("{:.1} kB", b / 1e3),
        Some(b) => format!("{b:.0} B"),
    }
}

/// The tables of `COMPARISON.md`: one row per strategy, the columns explained below the table,
/// the notes (coverage, PSNR, SSIM, errors) and the frame-time plot; `command` is the command
/// that made the comparison (recorded at the top).
pub fn render_markdown(
    rows: &[Row],
    formats: &[FormatRow],
    geometry: Option<&GeometryTimes>,
    command: &str,
) -> String {
    let mut m = String::new();
    let _ = writeln!(m, "# Far-field strategies compared\n");
    let _ = writeln!(m, "Made by:\n\n```\n{command}\n```\n");
    let geo_median = geometry.and_then(|g| g.median_ms);
    let culled_median = geometry.and_then(|g| g.culled_median_ms);
    if let Some(w) = rows.iter().find_map(|r| r.walk.as_ref()) {
        let _ = writeln!(
            m,
            "Walk: {} frames at {}×{}, adapter {}. Every strategy replays the same path; the all-geometry replays of that path: geometry-culled (frustum culling over Morton-ordered clusters, {} triangles per frame) median {} ms, p99 {} ms, GPU median {} ms; unculled median {} ms, p99 {} ms, GPU median {} ms.\n",
            w.stats.frames,
            w.size[0],
            w.size[1],
            w.adapter,
            geometry
                .and_then(|g| g.culled_mean_triangles)
                .map_or("–".into(), |t| format!("{t:.0}")),
            fmt_ms(culled_median),
            fmt_ms(geometry.and_then(|g| g.culled_p99_ms)),
            fmt_ms(geometry.and_then(|g| g.culled_gpu_median_ms)),
            fmt_ms(geo_median),
            fmt_ms(geometry.and_then(|g| g.p99_ms)),
            fmt_ms(geometry.and_then(|g| g.gpu_median_ms)),
        );
    }
    let _ = writeln!(
        m,
        "| strategy | bake s/cell | disk/cell | texture memory/cell | median ms | p99 ms | GPU median ms | speed-up vs culled | speed-up vs unculled | stalls | regenerations | far-field pixels | max px | p99 px | crack px | mean FLIP |"
    );
    let _ = writeln!(
        m,
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    let dash = || "–".to_string();
    for r in rows {
        let name = r.strategy.name();
        if !r.errors.is_empty() && r.walk.is_none() && r.eval.is_none() {
            let _ = writeln!(
                m,
                "| {name} | failed: see below | | | | | | | | | | | | | | |"
            );
            continue;
        }
        let walk = r.walk.as_ref();
        let per_cell = r.bake.as_ref().filter(|b| b.cells > 0).map(|b| {
            let c = b.cells as f64;
            (format!("{:.1}", b.seconds / c), b.bytes as f64 / c)
        });
        let bake_s = match r.strategy {
            StrategyKind::Warp => walk.map(|w| {
                let n = (w.prepared_cells as f64).max(1.0);
                format!("{:.1} (at run time)", w.prepare_seconds / n)
            }),
            StrategyKind::Dynamic => Some("none (at run time)".into()),
            _ => per_cell.as_ref().map(|p| p.0.clone()),
        };
        let disk = match r.strategy {
            StrategyKind::Warp | StrategyKind::Dynamic => "none".into(),
            _ => fmt_bytes(per_cell.map(|p| p.1)),
        };
        let median = walk.and_then(|w| w.stats.impostor_median_ms);
        let speedup_over = |base: Option<f64>| match (median, base) {
            (Some(a), Some(g)) if a > 0.0 => format!("{:.1}×", g / a),
            _ => dash(),
        };
        let (speedup_culled, speedup) = (speedup_over(culled_median), speedup_over(geo_median));
        let e = r.eval.as_ref();
        let px = |x: Option<Option<f32>>| match x {
            Some(Some(x)) => format!("{x:.2}"),
            Some(None) => "∞".into(),
            None => dash(),
        };
        let far_share = e.and_then(|e| {
            let all = e.views as f64 * e.size[0] as f64 * e.size[1] as f64;
            (all > 0.0).then(|| format!("{:.1} %", 100.0 * e.error_pixels as f64 / all))
        });
        let _ = writeln!(
            m,
            "| {name} | {} | {disk} | {} | {} | {} | {} | {speedup_culled} | {speedup} | {} | {} | {} | {} | {} | {} | {} |",
            bake_s.unwrap_or_else(dash),
            fmt_bytes(walk.map(|w| w.texture_bytes_per_cell)),
            fmt_ms(median),
            fmt_ms(walk.and_then(|w| w.stats.impostor_p99_ms)),
            fmt_ms(walk.and_then(|w| w.stats.impostor_gpu_median_ms)),
            walk.map_or_else(dash, |w| w.stats.stalls.to_string()),
            walk.map_or_else(dash, |w| w.regenerations.to_string()),
            far_share.unwrap_or_else(dash),
            px(e.map(|e| e.max_error_px)),
            px(e.map(|e| e.p99_error_px)),
            e.map_or_else(dash, |e| e.crack_pixels.to_string()),
            e.map_or_else(dash, |e| format!("{:.3}", e.mean_flip)),
        );
    }
    let _ = writeln!(
        m,
        "\nColumns: *bake s/cell* and *disk/cell* from the bake (seconds and bytes over \
         the cells baked); *texture memory/cell*: bytes of far-field textures the runtime held for \
         one cell; *median/p99 ms*: wall-clock frame time of the walk, until the GPU has \
         finished the frame, without reading it back (as a runtime presents it; warp finishes its \
         frames on the CPU), \
         *GPU median ms*: the render passes alone (timestamp queries; only for strategies whose \
         frame is all GPU work), \
         *speed-up vs culled*: the geometry-culled median (all geometry drawn as a renderer would \
         at least draw it: frustum culled over Morton-ordered clusters, the same image) over the \
         strategy's median, the speed-up to quote; *speed-up vs unculled*: the unculled \
         all-geometry median over the strategy's median; *stalls*: frames that waited \
         for a cell; *regenerations*: impostors regenerated (dynamic) or far fields recorded at \
         run time (warp); *far-field pixels*: share of the evaluated pixels drawn by the far field (the rest is near \
         geometry or background), the pixels the error columns are over; *max/p99 px*: geometric error of the far-field pixels in output pixels \
         (`lemi eval --strategy S`); *crack px*: pixels where the reference shows a surface and \
         the strategy shows background (layered strategies also count pixels showing something \
         farther than one slab behind); *mean FLIP*: mean over the views of the per-view mean \
         FLIP."
    );
    if !formats.is_empty() {
        texture_formats(&mut m, rows, formats);
    }
    let mut notes = String::new();
    for r in rows {
        if let Some(e) = &r.eval {
            let _ = writeln!(
                notes,
                "- {}: {} views evaluated, coverage {:.4}, PSNR {} dB, SSIM {:.3}.",
                r.strategy,
                e.views,
                e.coverage,
                e.psnr.map_or("∞".into(), |x| format!("{x:.1}")),
                e.ssim,
            );
        }
        for err in &r.errors {
            let _ = writeln!(notes, "- {} failed: {}", r.strategy, err.replace('\n', " "));
        }
    }
    for f in formats {
        for err in &f.errors {
            let _ = writeln!(
                notes,
                "- lemi with {} textures failed: {}",
                f.format,
                err.replace('\n', " ")
            );
        }
    }
    if !notes.is_empty() {
        let _ = writeln!(m, "\n{notes}");
    }
    let _ = writeln!(m, "\n![frame time per frame](frame_times.svg)");
    m
}

/// The table of the `lemi` bake per texture format: the `lemi` strategy's own bake first, then
/// every further format, each against the PNG bake where there is one.
fn texture_formats(m: &mut String, rows: &[Row], formats: &[FormatRow]) {
    let _ = writeln!(m, "\n## Texture formats of the `lemi` bake\n");
    let _ = writeln!(
        m,
        "| format | cell file/cell | textures on disk/cell | texture memory/cell | encode s/cell | mean FLIP | PSNR dB | crack px | FLIP vs PNG | PSNR vs PNG | changed coverage px |"
    );
    let _ = writeln!(m, "|---|---|---|---|---|---|---|---|---|---|---|");
    let lemi = rows.iter().find(|r| r.strategy == StrategyKind::Lemi);
    let lemi_textures = lemi
        .and_then(|r| r.eval.as_ref())
        .and_then(|e| e.textures.as_ref());
    // the PNG bake's texture memory, the 100 % of the memory column
    let png_memory = lemi_textures
        .filter(|t| t.format.is_png())
        .or_else(|| {
            (formats.iter())
                .filter(|f| f.format.is_png())
                .find_map(|f| f.eval.as_ref().and_then(|e| e.textures.as_ref()))
        })
        .map(|t| t.texture_memory_bytes_per_cell);
    let mut line = |format: TextureFormat,
                    bake: Option<&BakeRow>,
                    eval: Option<&EvalRow>,
                    against: Option<&AgainstResult>| {
        let dash = || "–".to_string();
        let t = eval.and_then(|e| e.textures.as_ref());
        let memory = t.map_or_else(dash, |t| {
            let share = png_memory.filter(|p| *p > 0.0).map_or(String::new(), |p| {
                format!(" ({:.0} %)", 100.0 * t.texture_memory_bytes_per_cell / p)
            });
            format!(
                "{}{share}",
                fmt_bytes(Some(t.texture_memory_bytes_per_cell))
            )
        });
        let encode = bake
            .and_then(|b| encode_seconds_per_cell(b, format))
            .map_or_else(dash, |(e, whole)| {
                format!(
                    "{e:.2} ({:.0} % of {whole:.1})",
                    100.0 * e / whole.max(1e-9)
                )
            });
        let psnr = |p: Option<f64>| p.map_or("∞".into(), |x| format!("{x:.2}"));
        let _ = writeln!(
            m,
            "| {} | {} | {} | {memory} | {encode} | {} | {} | {} | {} | {} | {} |",
            format.name(),
            fmt_bytes(t.map(|t| t.disk_bytes_per_cell)),
            fmt_bytes(t.map(|t| t.texture_bytes_per_cell)),
            eval.map_or_else(dash, |e| format!("{:.4}", e.mean_flip)),
            eval.map_or_else(dash, |e| psnr(e.psnr)),
            eval.map_or_else(dash, |e| e.crack_pixels.to_string()),
            against.map_or_else(dash, |a| format!("{:.4}", a.mean_flip)),
            against.map_or_else(dash, |a| psnr(a.psnr)),
            against.map_or_else(dash, |a| a.coverage_mismatch_pixels.to_string()),
        );
    };
    // the `lemi` strategy's own bake, unless it is one of the format rows
    if let (Some(r), Some(t)) = (lemi, lemi_textures) {
        if !formats.iter().any(|f| f.format == t.format) {
            line(t.format, r.bake.as_ref(), r.eval.as_ref(), None);
        }
    }
    for f in formats {
        line(
            f.format,
            f.bake.as_ref(),
            f.eval.as_ref(),
            f.against_png.as_ref(),
        );
    }
    let _ = writeln!(
        m,
        "\nColumns: per evaluated cell, the cell file and its macro-textures as stored (PNG, or \
         KTX2 with Zstandard), the texture memory they take in their stored format (RGBA8 for \
         PNG, the blocks for BC7 and BC1; share of the PNG bake's), the seconds of the bake's \
         encode stage (share of the cell's whole bake); *mean FLIP*, *PSNR*, *crack px* against \
         all geometry as above; *vs PNG*: the same views against the PNG bake's frames; \
         *changed coverage px*: pixels covered in one of the two frames only (the block formats \
         keep every texel's alpha exact; see docs/COMPRESSION.md for the pixel or so that a \
         different atlas layout can still change)."
    );
}

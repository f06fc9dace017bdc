//! Known-answer tests of the image metrics, the statistics and the report.

use lemi_eval::*;

const INF: f32 = f32::INFINITY;

/// A `w × h` test pattern: smooth gradients plus a checker, so FLIP and SSIM have structure.
fn pattern(w: u32, h: u32) -> Frame {
    let mut rgba = Vec::new();
    let mut depth = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let c = if (x / 4 + y / 4) % 2 == 0 { 40 } else { 0 };
            rgba.extend_from_slice(&[
                (x * 255 / w.max(1)) as u8 / 2 + c,
                (y * 255 / h.max(1)) as u8 / 2 + c,
                100 + c,
                255,
            ]);
            depth.push(10.0 + x as f32 * 0.1);
        }
    }
    Frame {
        width: w,
        height: h,
        rgba,
        depth,
    }
}

fn map_rgb(f: &Frame, g: impl Fn(usize, u8) -> u8) -> Frame {
    let mut out = f.clone();
    for (i, px) in out.rgba.chunks_exact_mut(4).enumerate() {
        for c in px.iter_mut().take(3) {
            *c = g(i, *c);
        }
    }
    out
}

fn no_tolerance(_: usize, _: f32) -> f32 {
    0.0
}

#[test]
fn identical_images() {
    let a = pattern(48, 32);
    let f = flip(&a, &a, ppd_default()).unwrap();
    assert_eq!(f.mean, 0.0);
    assert_eq!((f.width, f.height), (48, 32));
    assert_eq!(f.heatmap_rgba.len(), 48 * 32 * 4);
    assert_eq!(psnr(&a, &a).unwrap(), f64::INFINITY);
    assert!((ssim(&a, &a).unwrap() - 1.0).abs() < 1e-12);
    let cracks = crack_pixels(&a, &a, &no_tolerance).unwrap();
    assert_eq!(cracks.count, 0);
    assert!(cracks.first.is_empty());
    assert!(cracks.mask.iter().all(|&m| !m));
    let cov = coverage(&a, &a).unwrap();
    assert_eq!(cov.share, 1.0);
    assert_eq!(cov.reference_covered, 48 * 32);
    assert_eq!(cov.both, 48 * 32);
}

#[test]
fn background_where_reference_has_geometry_is_exactly_the_cracks() {
    let reference = pattern(20, 10);
    let mut test = reference.clone();
    let holes = [(3u32, 2u32), (19, 0), (0, 9), (7, 7)];
    for &(x, y) in &holes {
        test.depth[(y * 20 + x) as usize] = INF;
    }
    // Background in both is not a crack.
    let mut reference2 = reference.clone();
    reference2.depth[5] = INF;
    test.depth[5] = INF;
    let c = crack_pixels(&reference2, &test, &|_, _| 1e9).unwrap();
    assert_eq!(c.count, holes.len() as u64);
    let mut expected: Vec<(u32, u32)> = holes.to_vec();
    expected.sort_by_key(|&(x, y)| (y, x));
    assert_eq!(c.first, expected);
    for (i, &m) in c.mask.iter().enumerate() {
        let xy = ((i % 20) as u32, (i / 20) as u32);
        assert_eq!(m, holes.contains(&xy), "pixel {xy:?}");
    }
    let cov = coverage(&reference2, &test).unwrap();
    assert_eq!(cov.reference_covered, 199);
    assert_eq!(cov.test_covered, 199 - 4);
    assert_eq!(cov.both, 195);
    assert!((cov.share - 195.0 / 199.0).abs() < 1e-12);
}

#[test]
fn crack_samples_are_bounded() {
    let reference = pattern(40, 40);
    let mut test = reference.clone();
    test.depth.iter_mut().for_each(|d| *d = INF);
    let c = crack_pixels(&reference, &test, &no_tolerance).unwrap();
    assert_eq!(c.count, 1600);
    assert_eq!(c.first.len(), MAX_CRACK_SAMPLES);
    assert_eq!(c.first[1], (1, 0));
}

#[test]
fn farther_depth_beyond_tolerance_is_a_crack_within_is_not() {
    let reference = pattern(4, 1);
    let mut test = reference.clone();
    // Tolerance: 0.5 for pixel 0/1, 2.0 (a layer depth range) for the others; nearer is never a crack.
    let tol = |i: usize, _d: f32| if i < 2 { 0.5 } else { 2.0 };
    test.depth[0] += 0.4; // within 0.5
    test.depth[1] += 0.6; // beyond 0.5 → crack
    test.depth[2] += 2.5; // beyond 2.0 → crack
    test.depth[3] -= 5.0; // nearer → not
    let c = crack_pixels(&reference, &test, &tol).unwrap();
    assert_eq!(c.mask, vec![false, true, true, false]);
    assert_eq!(c.first, vec![(1, 0), (2, 0)]);
    // The tolerance sees the pixel index and the reference depth.
    let seen = std::cell::RefCell::new(Vec::new());
    crack_pixels(&reference, &test, &|i, d| {
        seen.borrow_mut().push((i, d));
        1.0
    })
    .unwrap();
    assert_eq!(seen.borrow()[2], (2, reference.depth[2]));
}

/// A 64×48 frame covering a disc of radius `r` around `(cx, cy)` (depth 5), background elsewhere.
fn disc(cx: f32, cy: f32, r: f32) -> Frame {
    let (w, h) = (64u32, 48u32);
    let mut f = Frame {
        width: w,
        height: h,
        rgba: vec![0; (4 * w * h) as usize],
        depth: vec![INF; (w * h) as usize],
    };
    for y in 0..h {
        for x in 0..w {
            let (dx, dy) = (x as f32 + 0.5 - cx, y as f32 + 0.5 - cy);
            if dx * dx + dy * dy <= r * r {
                let i = (y * w + x) as usize;
                f.depth[i] = 5.0;
                f.rgba[4 * i..4 * i + 4].copy_from_slice(&[200, 100, 50, 255]);
            }
        }
    }
    f
}

#[test]
fn silhouette_distances_of_known_shifts_and_growths() {
    let reference = disc(30.0, 24.0, 12.0);
    // identical: every distance 0, nothing falsely covered
    let same = silhouettes(&reference, &reference).unwrap();
    assert!(same.distances.count() > 50, "{}", same.distances.count());
    assert_eq!(same.distances.max(), 0.0);
    assert_eq!(same.false_coverage, 0);
    // shifted 3 px to the right: the outlines are 3 px apart where they are widest (left and
    // right), 0 where the shifted circles cross (top and bottom)
    let shifted = silhouettes(&reference, &disc(33.0, 24.0, 12.0)).unwrap();
    assert!(
        (2.5..=3.5).contains(&shifted.distances.max()),
        "max {}",
        shifted.distances.max()
    );
    assert!(shifted.distances.mean() > 0.5 && shifted.distances.mean() < 2.5);
    // fattened by 2 px (a silhouette a texel too fat): about 2 px all round, and the ring is
    // covered where the reference shows background (π·(14² − 12²) ≈ 163 pixels)
    let fat = silhouettes(&reference, &disc(30.0, 24.0, 14.0)).unwrap();
    assert!(
        (1.5..=2.5).contains(&fat.distances.max()),
        "max {}",
        fat.distances.max()
    );
    assert!(
        (1.3..=2.5).contains(&fat.distances.mean()),
        "{}",
        fat.distances.mean()
    );
    assert!(
        (140..=190).contains(&fat.false_coverage),
        "{}",
        fat.false_coverage
    );
    // thinned: no false coverage, the same distances
    let thin = silhouettes(&reference, &disc(30.0, 24.0, 10.0)).unwrap();
    assert_eq!(thin.false_coverage, 0);
    assert!((1.5..=2.5).contains(&thin.distances.max()));
    // a test frame with no outline at all (nothing drawn): infinitely far
    let mut empty = reference.clone();
    empty.depth.iter_mut().for_each(|d| *d = INF);
    assert_eq!(
        silhouettes(&reference, &empty).unwrap().distances.max(),
        INF
    );
    // a frame covering everything has no silhouette either (the image edge is none)
    let full = pattern(64, 48);
    let s = silhouettes(&full, &full).unwrap();
    assert_eq!(s.distances.count(), 0);
    assert!(silhouettes(&full, &pattern(32, 48)).is_err());
}

#[test]
fn coverage_displacement_sees_shifts_but_not_a_closed_slit_as_far() {
    let reference = disc(30.0, 24.0, 12.0);
    assert_eq!(
        silhouettes(&reference, &reference)
            .unwrap()
            .displacement
            .max(),
        0.0
    );
    // fattened by 2 px: the ring's pixels lie 1–2 px from the reference's coverage (its
    // Hausdorff distance is 2), thinned by 2 px the same from the other side
    for r in [14.0, 10.0] {
        let d = silhouettes(&reference, &disc(30.0, 24.0, r))
            .unwrap()
            .displacement;
        assert!(
            (1.5..=2.5).contains(&d.max()),
            "radius {r}: max {}",
            d.max()
        );
    }
    // shifted 3 px: the crescents' pixels up to 3 px from the other disc
    let d = silhouettes(&reference, &disc(33.0, 24.0, 12.0))
        .unwrap()
        .displacement;
    assert!((2.5..=3.5).contains(&d.max()), "max {}", d.max());
    // a one-pixel slit through the disc that the test closes: the outline metric finds the
    // slit's sides far from any outline of the test (up to about the radius), the displacement
    // only the slit's own pixels, one pixel from covered ones
    let mut slit = reference.clone();
    for y in 0..slit.height {
        let i = (y * slit.width + 30) as usize;
        slit.depth[i] = INF;
    }
    let s = silhouettes(&slit, &reference).unwrap();
    assert!(s.distances.max() > 8.0, "outline max {}", s.distances.max());
    assert_eq!(s.displacement.max(), 1.0);
    // the disc's rows at column 30 (pixel centres 0.5 px off its axis): 24
    assert_eq!(s.false_coverage, 24);
    // a thin feature the test drops where nothing else is near: as far as it is from the rest
    let mut pole = reference.clone();
    for y in 0..slit.height {
        let i = (y * slit.width + 60) as usize;
        pole.depth[i] = 5.0;
    }
    let s = silhouettes(&pole, &reference).unwrap();
    assert!(s.displacement.max() >= 18.0, "{}", s.displacement.max());
}

#[test]
fn psnr_of_constant_offset_is_closed_form() {
    let a = map_rgb(&pattern(16, 16), |_, c| c.min(200));
    for d in [1u8, 5, 17] {
        let b = map_rgb(&a, |_, c| c + d);
        let expected = 10.0 * (255.0f64 * 255.0 / (d as f64 * d as f64)).log10();
        let p = psnr(&a, &b).unwrap();
        assert!((p - expected).abs() < 1e-9, "offset {d}: {p} vs {expected}");
    }
    // Offset in one channel only: MSE = d² / 3.
    let b = {
        let mut b = a.clone();
        b.rgba.chunks_exact_mut(4).for_each(|p| p[1] += 10);
        b
    };
    let expected = 10.0 * (255.0f64 * 255.0 / (100.0 / 3.0)).log10();
    assert!((psnr(&a, &b).unwrap() - expected).abs() < 1e-9);
}

#[test]
fn alpha_is_ignored_by_colour_metrics() {
    let a = pattern(16, 16);
    let mut b = a.clone();
    b.rgba.chunks_exact_mut(4).for_each(|p| p[3] = 0);
    assert_eq!(psnr(&a, &b).unwrap(), f64::INFINITY);
    assert_eq!(flip(&a, &b, ppd_default()).unwrap().mean, 0.0);
}

#[test]
fn flip_grows_with_the_difference() {
    let a = pattern(64, 48);
    let small = map_rgb(&a, |i, c| if i % 7 == 0 { c.saturating_add(12) } else { c });
    let large = map_rgb(&a, |_, c| 255 - c);
    let f_small = flip(&a, &small, ppd_default()).unwrap();
    let f_large = flip(&a, &large, ppd_default()).unwrap();
    assert!(f_small.mean > 0.0);
    assert!(f_large.mean > 0.3, "inverted image FLIP {}", f_large.mean);
    assert!(f_small.mean < f_large.mean);
    assert!(f_large.error.iter().all(|e| (0.0..=1.0).contains(e)));
    // Heat map: alpha 255, and the identical case maps to the colour of 0.
    assert!(f_large.heatmap_rgba.chunks_exact(4).all(|p| p[3] == 255));
    // SSIM and PSNR order the same way.
    assert!(ssim(&a, &small).unwrap() > ssim(&a, &large).unwrap());
    assert!(psnr(&a, &small).unwrap() > psnr(&a, &large).unwrap());
    assert!(ssim(&a, &large).unwrap() < 0.5);
}

#[test]
fn ppd_helpers() {
    assert_eq!(ppd_default(), 67.0);
    // FLIP's default setup: 0.7 m from a 0.7 m wide 3840 px monitor ≈ 67 ppd.
    assert!((ppd_for_monitor(0.7, 3840.0, 0.7) - 67.0).abs() < 0.05);
    assert_eq!(ppd_for_view(1800, 90.0), 20.0);
}

#[test]
fn size_mismatch_is_an_error_naming_both_sizes() {
    let a = pattern(8, 6);
    let b = pattern(6, 8);
    let check = |e: EvalError| {
        let msg = e.to_string();
        assert!(msg.contains("8x6") && msg.contains("6x8"), "{msg}");
    };
    check(flip(&a, &b, 67.0).unwrap_err());
    check(psnr(&a, &b).unwrap_err());
    check(ssim(&a, &b).unwrap_err());
    check(coverage(&a, &b).unwrap_err());
    check(crack_pixels(&a, &b, &no_tolerance).unwrap_err());
    check(evaluate_view(&a, &b, &[0.0; 48], &no_tolerance, 67.0).unwrap_err());
    // Wrong error length.
    assert!(evaluate_view(&a, &a, &[0.0; 5], &no_tolerance, 67.0).is_err());
}

// ---- stats ----

#[test]
fn stats_of_a_known_distribution() {
    // 0.01, 0.02, …, 1.00 (100 values) + 1.5 and 3.0: 102 values.
    let mut values: Vec<f32> = (1..=100).map(|i| i as f32 / 100.0).collect();
    values.extend([1.5, 3.0, f32::NAN, f32::NAN]);
    let s = PixelErrorStats::from_values(&values);
    assert_eq!(s.count(), 102);
    assert_eq!(s.ignored_nan(), 2);
    assert_eq!(s.max(), 3.0);
    let exact_mean = (5050.0 / 100.0 + 4.5) / 102.0;
    assert!((s.mean() - exact_mean).abs() < 1e-6);
    assert_eq!(s.count_above_1px(), 2);
    assert!((s.share_above_1px() - 2.0 / 102.0).abs() < 1e-12);
    // Nearest rank: p99 of 102 values is the ceil(100.98) = 101st smallest = 1.5.
    let p99 = s.p99();
    assert!((1.5..=1.5 + 1.0 / 320.0).contains(&p99), "p99 {p99}");
    // Median: 51st smallest = 0.51.
    let p50 = s.quantile(0.5);
    assert!((0.51..=0.51 + 1.0 / 320.0).contains(&p50), "p50 {p50}");
    assert_eq!(s.quantile(1.0), 3.0);
    // Histogram: 0.05 px bins, values ≥ 4 px overflow.
    let h = s.histogram();
    assert_eq!(h.counts.len(), 80);
    assert_eq!(h.total(), 102);
    assert_eq!(h.overflow, 0);
    assert_eq!(h.counts[30], 1); // 1.5
    assert_eq!(h.counts[60], 1); // 3.0
}

#[test]
fn p99_of_a_uniform_sample_is_within_one_fine_bin() {
    let values: Vec<f32> = (0..10_000).map(|i| i as f32 * 0.0002).collect(); // 0 … 1.9998
    let s = PixelErrorStats::from_values(&values);
    let mut sorted = values.clone();
    sorted.sort_by(f32::total_cmp);
    let exact = sorted[(0.99f64 * 10_000.0).ceil() as usize - 1];
    let p = s.p99();
    assert!(p >= exact && p - exact <= 1.0 / 320.0, "{p} vs {exact}");
}

#[test]
fn merge_equals_the_union() {
    let a: Vec<f32> = (0..500).map(|i| (i as f32 * 0.37) % 2.3).collect();
    let b: Vec<f32> = (0..300)
        .map(|i| {
            if i % 10 == 0 {
                f32::NAN
            } else {
                i as f32 * 0.05
            }
        })
        .collect();
    let mut merged = PixelErrorStats::from_values(&a);
    merged.merge(&PixelErrorStats::from_values(&b));
    let union = PixelErrorStats::from_values(&[a.clone(), b.clone()].concat());
    assert_eq!(merged.count(), union.count());
    assert_eq!(merged.ignored_nan(), union.ignored_nan());
    assert_eq!(merged.max(), union.max());
    assert_eq!(merged.p99(), union.p99());
    assert_eq!(merged.histogram(), union.histogram());
    assert!((merged.mean() - union.mean()).abs() < 1e-9);
    // Merging an empty accumulator changes nothing, either way round.
    let mut e = PixelErrorStats::new();
    e.merge(&union);
    assert_eq!(e.p99(), union.p99());
    assert_eq!(e.max(), union.max());
    let mut u2 = union.clone();
    u2.merge(&PixelErrorStats::new());
    assert_eq!(u2, union);
    // Histograms merge too.
    let mut ha = PixelErrorStats::from_values(&a).histogram();
    ha.merge(&PixelErrorStats::from_values(&b).histogram());
    assert_eq!(ha, union.histogram());
}

// ---- report ----

fn sample_bundle() -> (BundleResult, Vec<WorstView>) {
    let reference = pattern(32, 24);
    let mut impostor = map_rgb(&reference, |i, c| if i % 5 == 0 { c / 2 } else { c });
    impostor.depth[33] = INF;
    let mut cells = Vec::new();
    let mut worst = WorstSet::new(2);
    for cell in ["cell 0_0_0", "cell <1_0_0>"] {
        let mut stats = PixelErrorStats::new();
        let mut views = Vec::new();
        for corner in 0..3 {
            let err: Vec<f32> = (0..32 * 24)
                .map(|i| {
                    if i % 11 == 0 {
                        f32::NAN
                    } else {
                        (i % 97) as f32 * 0.01 * (corner + 1) as f32
                    }
                })
                .collect();
            let e = evaluate_view(&reference, &impostor, &err, &|_, _| 0.5, ppd_default()).unwrap();
            stats.merge(&e.error);
            let v = e.result(
                cell,
                format!("corner {corner}"),
                [corner as f64, 0.0, 1.5],
                [0.0, 0.0, -1.0],
            );
            worst.offer(&v, || WorstView {
                label: format!("{cell} / corner {corner}"),
                reference: reference.clone(),
                impostor: impostor.clone(),
                flip_heatmap: e.flip.heatmap_rgba.clone(),
            });
            views.push(v);
        }
        cells.push(CellResult::new(cell, views, stats));
    }
    (
        BundleResult::new(cells).with_info("bundle", "city.lemi"),
        worst.into_worst_views(),
    )
}

#[test]
fn aggregation_per_cell_and_bundle() {
    let (b, worst) = sample_bundle();
    assert_eq!(worst.len(), 2);
    assert_eq!(b.summary.views, 6);
    assert_eq!(b.cells[0].summary.views, 3);
    assert_eq!(b.summary.crack_pixels, 6);
    assert_eq!(b.summary.views_with_cracks, 6);
    // the one crack pixel of every view (depth 33 of a 32-wide frame: x 1, y 1), where it is
    for v in b.cells.iter().flat_map(|c| &c.view_results) {
        assert_eq!(v.crack_samples, vec![[1, 1]], "{}", v.viewpoint);
    }
    // max error: 96 * 0.01 * 3.
    assert!((b.summary.max_error_px - 2.88).abs() < 1e-5);
    assert_eq!(b.summary.max_error_px, b.cells[1].summary.max_error_px);
    let mut merged = b.cells[0].error_stats().clone();
    merged.merge(b.cells[1].error_stats());
    assert_eq!(b.summary.p99_error_px, merged.p99());
    assert_eq!(b.summary.error_pixels, merged.count());
    assert!(b.summary.mean_flip > 0.0);
    assert!((b.summary.mean_flip - b.cells[0].summary.mean_flip).abs() < 1e-6);
    assert!(b.summary.coverage < 1.0);
    assert_eq!(b.worst_views.len(), 6);
    assert_eq!(b.cells[0].worst_views[0].viewpoint, "corner 2");
    let v = verdict(&b);
    assert_eq!(
        v,
        format!(
            "max error 2.88 px (p99 {:.2} px), 6 crack pixels, mean FLIP {:.3} over 6 views",
            b.summary.p99_error_px, b.summary.mean_flip
        )
    );
}

#[test]
fn verdict_format() {
    let mut stats = PixelErrorStats::new();
    stats.add_all(&[0.9, 0.4, 0.1]);
    let view = ViewResult {
        cell: "c".into(),
        viewpoint: "centre".into(),
        eye: [0.0; 3],
        dir: [0.0, 0.0, -1.0],
        error: ErrorSummary::of(&stats),
        crack_pixels: 0,
        crack_samples: Vec::new(),
        mean_flip: 0.031,
        psnr: f64::INFINITY,
        ssim: 1.0,
        coverage: 1.0,
        silhouette: ErrorSummary::default(),
        displacement: ErrorSummary::default(),
        false_coverage_pixels: 0,
        pixels: 1,
        silhouette_floor: None,
    };
    let b = BundleResult::new(vec![CellResult::new("c", vec![view], stats)]);
    assert_eq!(
        verdict(&b),
        "max error 0.90 px (p99 0.90 px), 0 crack pixels, mean FLIP 0.031 over 1 views"
    );
    assert_eq!(b.summary.psnr, f64::INFINITY);
    // Infinite PSNR survives a JSON round trip (as null).
    let json = serde_json::to_string(&b).unwrap();
    let back: BundleResult = serde_json::from_str(&json).unwrap();
    assert_eq!(back.summary.psnr, f64::INFINITY);
    assert_eq!(back.cells[0].view_results[0], b.cells[0].view_results[0]);
    assert_eq!(back.summary, b.summary);
    // a view without cracks has no crack samples in its JSON
    assert!(!json.contains("crack_samples"), "{json}");
}

#[test]
fn report_is_written_local_and_complete() {
    let (b, worst) = sample_bundle();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("eval-out");
    let index = write_report(&out, &b, &worst).unwrap();
    assert_eq!(index, out.join("index.html"));
    let html = std::fs::read_to_string(&index).unwrap();
    assert!(html.contains(&verdict(&b)), "verdict missing");
    assert!(html.contains("<tr id=\"cell-0\""));
    assert!(html.contains("<tr id=\"cell-1\""));
    assert!(html.contains("cell 0_0_0"));
    assert!(
        html.contains("cell &lt;1_0_0&gt;"),
        "cell names are escaped"
    );
    assert!(!html.contains("cell <1_0_0>"));
    assert!(html.contains("<svg"), "histograms are inline SVG");
    // Only local references: every src/href names a file in the directory.
    for attr in ["src=\"", "href=\""] {
        for part in html.split(attr).skip(1) {
            let target = &part[..part.find('"').unwrap()];
            assert!(
                !target.contains("//") && !target.contains(':'),
                "non-local {target}"
            );
            assert!(out.join(target).is_file(), "{target} missing");
        }
    }
    for l in html.match_indices("http") {
        let rest = &html[l.0..];
        assert!(
            rest.starts_with("http://www.w3.org/2000/svg"),
            "network reference {}",
            &rest[..40.min(rest.len())]
        );
    }
    assert!(out.join("worst-00.png").is_file() && out.join("worst-01.png").is_file());
    let png = image::open(out.join("worst-00.png")).unwrap();
    assert_eq!((png.width(), png.height()), (3 * 32 + 8, 24));
    // No temporary files left behind.
    for e in std::fs::read_dir(&out).unwrap() {
        let name = e.unwrap().file_name().to_string_lossy().into_owned();
        assert!(!name.starts_with('.'), "leftover {name}");
    }
    // JSON with the required keys, per bundle and per cell.
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("report.json")).unwrap()).unwrap();
    let keys = [
        "views",
        "max_error_px",
        "p99_error_px",
        "crack_pixels",
        "mean_flip",
        "coverage",
    ];
    for k in keys {
        assert!(json.get(k).is_some(), "bundle key {k}");
    }
    let cells = json["cells"].as_array().unwrap();
    assert_eq!(cells.len(), 2);
    for c in cells {
        for k in keys {
            assert!(c.get(k).is_some(), "cell key {k}");
        }
        assert!(c["cell"].is_string());
    }
    assert_eq!(json["views"], 6);
    assert_eq!(json["crack_pixels"], 6);
    assert_eq!(json["info"]["bundle"], "city.lemi");
    // every view says where its crack pixel is
    let v = &cells[0]["view_results"][0];
    assert_eq!(v["crack_samples"], serde_json::json!([[1, 1]]), "{v}");
    // Writing again replaces atomically.
    write_report(&out, &b, &[]).unwrap();
}

#[test]
fn report_rejects_mismatched_worst_view() {
    let (b, mut worst) = sample_bundle();
    worst[0].flip_heatmap.truncate(10);
    let dir = tempfile::tempdir().unwrap();
    assert!(write_report(dir.path(), &b, &worst).is_err());
    worst[0].impostor = pattern(5, 5);
    let e = write_report(dir.path(), &b, &worst)
        .unwrap_err()
        .to_string();
    assert!(e.contains("32x24") && e.contains("5x5"), "{e}");
}

/// `frame` with `rect` (`[x0, y0, x1, y1)`) covered at depth 5.
fn cover(mut frame: Frame, [x0, y0, x1, y1]: [u32; 4]) -> Frame {
    for y in y0..y1 {
        for x in x0..x1 {
            let i = (y * frame.width + x) as usize;
            frame.depth[i] = 5.0;
            frame.rgba[4 * i..4 * i + 4].copy_from_slice(&[200, 100, 50, 255]);
        }
    }
    frame
}

/// An empty `w × h` frame.
fn blank(w: u32, h: u32) -> Frame {
    Frame {
        width: w,
        height: h,
        rgba: vec![0; (4 * w * h) as usize],
        depth: vec![INF; (w * h) as usize],
    }
}

/// The `width × height` frame inside a guard band of `g` pixels.
fn inner(frame: &Frame, g: u32, width: u32, height: u32) -> Frame {
    let mut out = blank(width, height);
    for y in 0..height {
        for x in 0..width {
            let (i, o) = (
                ((y + g) * frame.width + x + g) as usize,
                (y * width + x) as usize,
            );
            out.depth[o] = frame.depth[i];
            out.rgba[4 * o..4 * o + 4].copy_from_slice(&frame.rgba[4 * i..4 * i + 4]);
        }
    }
    out
}

/// A bar just beyond the output view's right edge in the reference, one pixel wider (into the
/// view's last column) in the test: on frames of the view alone that column is far from everything
/// the reference covers in the view (the distance is overstated, and `edge_bound` says so); inside
/// frames with a guard band it is 1 px from the reference's bar, as it is.
#[test]
fn a_guard_band_measures_what_lies_beyond_the_image_edge() {
    let (w, h, g) = (64u32, 48u32, 4u32);
    let band = GuardBand {
        px: g,
        width: w,
        height: h,
    };
    // a block in the middle of the view in both, the bar at columns w..w+2 of the view (beyond
    // it) in the reference and w−1..w+2 in the test
    let both = |f: Frame| cover(f, [g + 20, g + 20, g + 30, g + 40]);
    let reference = cover(
        both(blank(w + 2 * g, h + 2 * g)),
        [g + w, g + 5, g + w + 2, g + 15],
    );
    let test = cover(
        both(blank(w + 2 * g, h + 2 * g)),
        [g + w - 1, g + 5, g + w + 2, g + 15],
    );
    let alone = silhouettes(&inner(&reference, g, w, h), &inner(&test, g, w, h)).unwrap();
    assert!(alone.edge_bound);
    assert!(
        alone.displacement.max() > 20.0,
        "{}",
        alone.displacement.max()
    );
    assert_eq!(alone.false_coverage, 10);
    let banded = silhouettes_within(&reference, &test, band).unwrap();
    assert!(!banded.edge_bound);
    assert_eq!(banded.displacement.max(), 1.0);
    assert_eq!(banded.false_coverage, 10);
    // away from the edge the band changes nothing: the same statistics as the view alone
    let shifted = cover(
        both(blank(w + 2 * g, h + 2 * g)),
        [g + 40, g + 10, g + 50, g + 20],
    );
    let moved = cover(
        both(blank(w + 2 * g, h + 2 * g)),
        [g + 42, g + 11, g + 52, g + 21],
    );
    let a = silhouettes(&inner(&shifted, g, w, h), &inner(&moved, g, w, h)).unwrap();
    let b = silhouettes_within(&shifted, &moved, band).unwrap();
    assert!(!a.edge_bound && !b.edge_bound);
    assert_eq!(a.displacement.max(), b.displacement.max());
    assert_eq!(a.distances.max(), b.distances.max());
    assert_eq!(a.displacement.count(), b.displacement.count());
    assert_eq!(a.false_coverage, b.false_coverage);
    // a view that does not fit its frame is an error
    assert!(silhouettes_within(&inner(&shifted, g, w, h), &moved, band).is_err());
}

/// The pooled p99 of the outlines is that of all silhouette pixels of all views together, which a
/// view whose few far outline pixels set its own p99 does not set: one view of 200 pixels at
/// 0.5 px, one of 99 at 0.5 px and 2 at 3 px (its p99: 3 px; pooled, 2 of 301 pixels: 0.5 px).
#[test]
fn pooled_outline_p99_is_over_all_silhouette_pixels_of_all_views() {
    let view_of = |values: &[f32]| {
        let s = PixelErrorStats::from_values(values);
        let view = ViewResult {
            cell: "c".into(),
            viewpoint: "v".into(),
            eye: [0.0; 3],
            dir: [0.0, 0.0, -1.0],
            error: ErrorSummary::default(),
            crack_pixels: 0,
            crack_samples: Vec::new(),
            mean_flip: 0.0,
            psnr: f64::INFINITY,
            ssim: 1.0,
            coverage: 1.0,
            silhouette: ErrorSummary::of(&s),
            displacement: ErrorSummary::of(&s),
            false_coverage_pixels: 0,
            pixels: 1,
            silhouette_floor: None,
        };
        (view, s)
    };
    let (a, sa) = view_of(&[0.5; 200]);
    let mut far = vec![0.5f32; 99];
    far.extend([3.0, 3.0]);
    let (b, sb) = view_of(&far);
    assert_eq!(b.silhouette.p99, 3.0);
    let mut outlines = OutlineStats::default();
    for s in [&sa, &sb] {
        outlines.silhouette.merge(s);
        outlines.displacement.merge(s);
    }
    let cell =
        CellResult::new("c", vec![a, b], PixelErrorStats::new()).with_outline_stats(outlines);
    let bundle = BundleResult::new(vec![cell]);
    for s in [&bundle.cells[0].summary, &bundle.summary] {
        assert_eq!(s.silhouette_p99_px, 3.0, "the worst view's p99");
        assert!((s.silhouette_pooled_p99_px - 0.5).abs() <= 1.0 / 320.0 + 1e-6);
        assert!((s.displacement_pooled_p99_px - 0.5).abs() <= 1.0 / 320.0 + 1e-6);
        assert_eq!(s.silhouette_max_px, 3.0);
    }
    // without the per-pixel statistics (an older report), the pooled values stay 0
    let plain = BundleResult::new(vec![CellResult::new(
        "c",
        vec![view_of(&far).0],
        PixelErrorStats::new(),
    )]);
    assert_eq!(plain.summary.silhouette_pooled_p99_px, 0.0);
}

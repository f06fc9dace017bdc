//! How long the built-in scenes take to build, and what they hold (a measurement, not a test):
//! `cargo run --release -p lemi-scene --example builtin_build_times [SPEC…]` (default: the 1 M
//! city, the 5 M city, the 1 M terrain and the 1 M forest).

use lemi_scene::builtin;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let specs: Vec<String> = if args.is_empty() {
        ["city:1M:1", "city:5M:1", "terrain:1M:1", "forest:1M:1"]
            .map(String::from)
            .to_vec()
    } else {
        args
    };
    for spec in &specs {
        let t0 = std::time::Instant::now();
        let s = match builtin::build(spec) {
            Ok(s) => s,
            Err(e) => {
                eprintln!("error: {spec}: {e}");
                std::process::exit(2);
            }
        };
        let dt = t0.elapsed();
        let size = s.bounds.size();
        println!(
            "{spec}: {} triangles, {} vertices, {} meshes, {:.2} s, extent {:.0} x {:.0} x {:.0} m",
            s.triangle_count(),
            s.stats.vertices,
            s.meshes.len(),
            dt.as_secs_f64(),
            size.x,
            size.y,
            size.z
        );
        let mut per_material = vec![(0u64, glam::DVec3::MAX, glam::DVec3::MIN); s.materials.len()];
        for m in &s.meshes {
            let Some(e) = per_material.get_mut(m.material as usize) else {
                continue;
            };
            e.0 += m.triangle_count() as u64;
            for v in &m.vertices {
                let p = glam::DVec3::from(v.position.map(f64::from));
                e.1 = e.1.min(p);
                e.2 = e.2.max(p);
            }
        }
        for (mat, (tris, lo, hi)) in s.materials.iter().zip(per_material) {
            println!(
                "    {:<18} {:>9} triangles, x {:.0}..{:.0}, z {:.0}..{:.0}",
                mat.name, tris, lo.x, hi.x, lo.z, hi.z
            );
        }
    }
}

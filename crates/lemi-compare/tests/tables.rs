//! The GPU-free parts of a comparison: the strategy list check and `COMPARISON.md` of rows that
//! failed or have only some of their numbers.

use lemi_compare::{check_strategies, render_markdown, CompareError, GeometryTimes, Row};
use lemi_strategy::StrategyKind;

fn row(strategy: StrategyKind, errors: &[&str]) -> Row {
    Row {
        strategy,
        bundle: None,
        bake: None,
        walk: None,
        eval: None,
        errors: errors.iter().map(|e| e.to_string()).collect(),
        frames: Vec::new(),
    }
}

#[test]
fn the_strategies_are_distinct_and_at_least_one() {
    use StrategyKind::*;
    assert!(check_strategies(&[Lemi, Warp]).is_ok());
    assert!(matches!(
        check_strategies(&[]),
        Err(CompareError::NoStrategies)
    ));
    let e = check_strategies(&[Warp, Lemi, Warp]).unwrap_err();
    assert!(matches!(e, CompareError::Repeated(Warp)));
    assert_eq!(e.to_string(), "`warp` is listed twice");
}

#[test]
fn the_tables_name_every_strategy_and_every_failure() {
    let rows = [
        row(StrategyKind::Lemi, &[]),
        row(StrategyKind::Cubemap, &["bake (cubemap): no\nGPU"]),
    ];
    let geometry = GeometryTimes {
        median_ms: Some(10.0),
        culled_median_ms: Some(4.0),
        culled_mean_triangles: Some(1234.0),
        ..Default::default()
    };
    let md = render_markdown(&rows, &[], Some(&geometry), "lemi compare builtin:city");
    assert!(md.starts_with("# Far-field strategies compared\n"), "{md}");
    assert!(md.contains("```\nlemi compare builtin:city\n```"), "{md}");
    assert!(md.contains("| lemi | – | – |"), "{md}");
    assert!(md.contains("| cubemap | failed: see below |"), "{md}");
    // the speed-up is quoted against geometry-culled, the unculled one beside it
    assert!(
        md.contains("| speed-up vs culled | speed-up vs unculled |"),
        "{md}"
    );
    assert!(
        md.contains("geometry-culled (frustum culling") || !md.contains("Walk:"),
        "{md}"
    );
    let columns = |l: &str| l.matches('|').count();
    let header = md.lines().find(|l| l.starts_with("| strategy |")).unwrap();
    let failed = md.lines().find(|l| l.starts_with("| cubemap |")).unwrap();
    assert_eq!(columns(header), columns(failed), "{md}");
    assert!(
        md.contains("- cubemap failed: bake (cubemap): no GPU"),
        "{md}"
    );
    assert!(
        md.ends_with("![frame time per frame](frame_times.svg)\n"),
        "{md}"
    );
}

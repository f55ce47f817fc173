//! Composed courses (issue 44): for every kind of feature the generator
//! strings along a route, one course that must have it (`shoal gen --course
//! composed --with <kind>`, the rest of the course drawn from the course
//! seed), run with the paper's five to the end: `shoal check` accepts the
//! file, the header names the feature, and the run passes by the campaign's
//! criteria with no collision of either kind.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use shoal_tests::*;

const KINDS: [&str; 9] = [
    "gap",
    "turn",
    "u-turn",
    "s-bend",
    "cylinders",
    "spheres",
    "walls",
    "depth",
    "current",
];

/// What the header's description says for each kind.
fn said(kind: &str) -> &'static [&'static str] {
    match kind {
        "gap" => &["a gap "],
        "turn" | "u-turn" => &["a turn of "],
        "s-bend" => &["an S-bend of "],
        "cylinders" => &[" cylinder"],
        "spheres" => &[" sphere"],
        "walls" => &["a funnel at ", "a skewed channel at "],
        "depth" => &["down ", "up "],
        "current" => &["a current of "],
        _ => unreachable!(),
    }
}

fn run_kind(kind: &str, dir: &std::path::Path) {
    let o = run_shoal(&[
        "gen",
        "--shape",
        "paper",
        "--course",
        "composed",
        "--course-seed",
        "1",
        "--with",
        kind,
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8(o.stdout).unwrap();
    let header: String = text
        .lines()
        .take_while(|l| l.starts_with('#'))
        .collect::<Vec<_>>()
        .join("\n");
    assert!(
        said(kind).iter().any(|s| header.contains(s)),
        "{kind}: {header}"
    );
    let file = dir.join(format!("{kind}.toml"));
    std::fs::write(&file, &text).unwrap();
    run_shoal_ok(&["check", file.to_str().unwrap()]);
    let out = dir.join(kind);
    run_shoal_ok(&[
        "run",
        file.to_str().unwrap(),
        "--quiet",
        "--out",
        out.to_str().unwrap(),
    ]);
    let s = summary(&out);
    assert_eq!(s["safety"]["collisions"], 0, "{kind}");
    assert_eq!(
        s["safety"]["obstacle_contacts"].as_array().map(Vec::len),
        Some(0),
        "{kind}: {}",
        s["safety"]["obstacle_contacts"]
    );
    assert_eq!(s["verdict"]["pass"], true, "{kind}: {}", s["verdict"]);
}

#[test]
fn one_composed_course_per_kind_of_feature_passes() {
    let tmp = tempfile::tempdir().unwrap();
    for kind in KINDS {
        run_kind(kind, tmp.path());
    }
}

#[test]
fn with_needs_a_composed_course() {
    let o = run_shoal(&[
        "gen", "--shape", "paper", "--course", "gate", "--with", "walls",
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("--with needs --course composed"), "{err}");
}

/// Know before you go (issue 45): `shoal check` says the narrowest gap the
/// formation passes at the safe distance and the narrowest opening on the
/// route, and warns when the route's is narrower: the paper's passage is
/// 8 m, as narrow as its five pass; walls 2 m nearer the track make it 4 m.
#[test]
fn check_warns_of_an_opening_narrower_than_the_formation_passes() {
    let tmp = tempfile::tempdir().unwrap();
    let paper = std::fs::read_to_string(repo_root().join("scenarios/paper.toml")).unwrap();
    let o = run_shoal_ok(&[
        "check",
        repo_root().join("scenarios/paper.toml").to_str().unwrap(),
    ]);
    let said = String::from_utf8_lossy(&o.stdout).to_string();
    assert!(
        said.contains("narrowest gap it passes at the safe distance (2 m): 8.0 m"),
        "{said}"
    );
    assert!(
        said.contains("route: narrowest opening 8.0 m wide"),
        "{said}"
    );
    assert!(!said.contains("warning: the route passes"), "{said}");
    let narrow = paper
        .replace("[70.0, -9.0, 10.0]", "[70.0, -7.0, 10.0]")
        .replace("[70.0, 9.0, 10.0]", "[70.0, 7.0, 10.0]");
    let file = tmp.path().join("narrow.toml");
    std::fs::write(&file, narrow).unwrap();
    let o = run_shoal_ok(&["check", file.to_str().unwrap()]);
    let said = String::from_utf8_lossy(&o.stdout).to_string();
    assert!(
        said.contains("warning: the route passes an opening 4.0 m wide"),
        "{said}"
    );
}
